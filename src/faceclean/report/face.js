// faceclean's 3D face view: one mesh drawn twice side by side (input left, cleaned
// right), posed by ARKit-52 weights. Shared by the HTML report (report/viewer.js, inlined
// as the "faceclean/face" module) and the tuning page (ui/static/ui.js, served).
// The mesh is report/payload.py's: base64 float32 positions, uint32 triangles, uint8
// colours, and per target the vertices it moves with int16 deltas times a scale q.
import * as THREE from "three";

export function decode(b64, Type) {
  const bin = atob(b64);
  const bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
  return new Type(bytes.buffer);
}

// The view on `canvas`: fit() after a resize, show([w_left, w_right], heads) poses and
// draws both faces ((52,) weights each; heads, optional: [yaw, pitch, roll] rad or null
// per face, turning it about a neck pivot in glTF's frame: faceclean/pose.py, Euler
// "YXZ" of pitch, -yaw, -roll), renders counts the frames drawn, heads gives each face's
// head rotation as a quaternion [x, y, z, w].
// True when WebGL draws on the CPU (SwiftShader, llvmpipe: a machine without a GPU, or a
// browser that has turned it off): a page beside a live relay then draws lighter.
export function softwareGL() {
  const probe = document.createElement("canvas");
  const gl = probe.getContext("webgl2") || probe.getContext("webgl");
  if (!gl) return false;
  const info = gl.getExtension("WEBGL_debug_renderer_info");
  const name = String(gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
  gl.getExtension("WEBGL_lose_context")?.loseContext();
  return /swiftshader|llvmpipe|softpipe|software/i.test(name);
}

// `light`: for a view that redraws live next to work that needs the CPU (software GL):
// no multisampling, half a sample a CSS pixel each way (a quarter of the fragments), and
// light computed per vertex (Lambert) instead of per fragment (physically based).
export function faceView(canvas, m, background = 0xe9edf2, { light = false } = {}) {
  const base = decode(m.positions, Float32Array); // (V*3) mesh units
  const index = decode(m.indices, Uint32Array);
  const colors = m.colors ? decode(m.colors, Uint8Array) : null;
  const tidx = decode(m.target_index, Uint32Array); // concatenated vertex indices
  const tdel = decode(m.target_delta, Int16Array); // (sum n, 3) deltas / q
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: !light, preserveDrawingBuffer: true });
  renderer.setPixelRatio(light ? 0.5 : Math.min(window.devicePixelRatio || 1, 2));
  renderer.setClearColor(background);
  const scene = new THREE.Scene();
  scene.add(new THREE.HemisphereLight(0xffffff, 0x8d7f78, 1.4));
  const key = new THREE.DirectionalLight(0xffffff, 2.2);
  key.position.set(-0.6, 0.8, 1.2);
  scene.add(key);
  const fill = new THREE.DirectionalLight(0xdfe8ff, 0.7);
  fill.position.set(0.9, 0.1, 0.6);
  scene.add(fill);

  const min = [Infinity, Infinity, Infinity], max = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < base.length; i += 3) {
    for (let k = 0; k < 3; k++) {
      min[k] = Math.min(min[k], base[i + k]);
      max[k] = Math.max(max[k], base[i + k]);
    }
  }
  const size = [max[0] - min[0], max[1] - min[1], max[2] - min[2]];
  const centre = [(max[0] + min[0]) / 2, (max[1] + min[1]) / 2, (max[2] + min[2]) / 2];
  const look = { vertexColors: !!colors, color: colors ? 0xffffff : 0xe8bfa8, side: THREE.DoubleSide };
  const material = light
    ? new THREE.MeshLambertMaterial(look)
    : new THREE.MeshStandardMaterial({ ...look, roughness: 0.62, metalness: 0.0 });
  // the neck pivot the head turns about: behind the jaw, low in the face's bounding box
  const pivot = [centre[0], min[1] + 0.2 * size[1], centre[2] - 0.15 * size[2]];
  const faces = [];
  for (const side of [-1, 1]) {
    const geometry = new THREE.BufferGeometry();
    const pos = new Float32Array(base);
    geometry.setAttribute("position", new THREE.BufferAttribute(pos, 3));
    if (colors) geometry.setAttribute("color", new THREE.BufferAttribute(colors, 3, true));
    geometry.setIndex(new THREE.BufferAttribute(index, 1));
    geometry.computeVertexNormals();
    const mesh = new THREE.Mesh(geometry, material);
    const holder = new THREE.Group(); // at the pivot: turned to the camera, then by the head
    mesh.position.set(-pivot[0], -pivot[1], -pivot[2]);
    holder.add(mesh);
    scene.add(holder);
    const facing = new THREE.Quaternion(), head = new THREE.Quaternion();
    faces.push({ geometry, pos, weights: null, mesh, holder, facing, head, side });
  }
  const euler = new THREE.Euler(0, 0, 0, "YXZ");
  const before = new THREE.Quaternion();
  // false when the head already has that turn
  function turn(face, ypr) {
    before.copy(face.head);
    if (ypr) face.head.setFromEuler(euler.set(ypr[1], -ypr[0], -ypr[2], "YXZ"));
    else face.head.identity();
    face.holder.quaternion.copy(face.facing).multiply(face.head);
    return !before.equals(face.head);
  }
  const camera = new THREE.PerspectiveCamera(24, 2, size[1] * 0.05, size[1] * 60);
  let renders = 0;
  const draw = () => { renderer.render(scene, camera); renders++; };

  // false when the face already shows w (nothing to draw)
  function pose(face, w) {
    if (face.weights && face.weights.every((x, j) => Math.abs(x - w[j]) < 1e-5)) return false;
    face.weights = Array.from(w);
    const p = face.pos;
    p.set(base);
    let start = 0;
    for (const tg of m.targets) {
      const wj = w[tg.ch];
      if (Math.abs(wj) > 1e-4) {
        const s = wj * tg.q;
        for (let i = start; i < start + tg.n; i++) {
          const v = 3 * tidx[i];
          p[v] += s * tdel[3 * i];
          p[v + 1] += s * tdel[3 * i + 1];
          p[v + 2] += s * tdel[3 * i + 2];
        }
      }
      start += tg.n;
    }
    face.geometry.attributes.position.needsUpdate = true;
    face.geometry.computeVertexNormals();
    return true;
  }

  return {
    fit() {
      const w = canvas.clientWidth, h = canvas.clientHeight;
      if (!w || !h) return;
      renderer.setSize(w, h, false);
      camera.aspect = w / h;
      // Each face fills its half of the view: height and half the width both fit.
      const tan = Math.tan((camera.fov * Math.PI) / 360);
      const dist = Math.max((size[1] * 1.08) / (2 * tan), (size[0] * 2.3) / (2 * tan * camera.aspect));
      const width = 2 * dist * tan * camera.aspect; // visible width at the faces' plane
      for (const f of faces) {
        const x = (f.side * width) / 4;
        f.holder.position.set(x + pivot[0] - centre[0], pivot[1] - centre[1], pivot[2] - centre[2]);
        const yaw = -Math.atan2(x, dist + size[2] / 2); // face the camera squarely
        f.facing.setFromAxisAngle(new THREE.Vector3(0, 1, 0), yaw);
        f.holder.quaternion.copy(f.facing).multiply(f.head);
      }
      camera.position.set(0, size[1] * 0.03, dist + size[2] / 2);
      camera.lookAt(0, 0, 0);
      camera.updateProjectionMatrix();
      draw();
    },
    // poses and draws both faces; draws nothing when neither face changed
    show(weights, heads = null) {
      let changed = renders === 0;
      faces.forEach((face, k) => {
        changed = pose(face, weights[k]) || changed;
        changed = turn(face, heads ? heads[k] : null) || changed;
      });
      if (changed) draw();
    },
    get renders() { return renders; },
    get heads() { return faces.map((f) => f.head.toArray()); },
  };
}
