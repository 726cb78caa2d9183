// node load_gltf.mjs FILE: load FILE with three.js's GLTFLoader (headless, via parse) and
// print, as JSON: the morph target names of each mesh, and each clip's tracks (name,
// times, values) and duration. Run from the repository root (node_modules/three).
import fs from "fs";
import path from "path";
import { pathToFileURL } from "url";

const root = pathToFileURL(path.resolve("node_modules/three") + "/").href;
const { GLTFLoader } = await import(root + "examples/jsm/loaders/GLTFLoader.js");

const bytes = fs.readFileSync(process.argv[2]);
const buffer = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
new GLTFLoader().parse(
  buffer,
  "",
  (gltf) => {
    const meshes = [];
    gltf.scene.traverse((o) => {
      if (o.isMesh) {
        meshes.push({
          name: o.name,
          vertices: o.geometry.attributes.position.count,
          targets: Object.keys(o.morphTargetDictionary || {}),
          influences: o.morphTargetInfluences.length,
        });
      }
    });
    const clips = gltf.animations.map((c) => ({
      name: c.name,
      duration: c.duration,
      tracks: c.tracks.map((t) => ({
        name: t.name,
        interpolation: t.getInterpolation(),
        times: Array.from(t.times),
        values: Array.from(t.values),
      })),
    }));
    process.stdout.write(JSON.stringify({ meshes, clips }));
  },
  (error) => {
    process.stderr.write(String(error) + "\n");
    process.exit(1);
  },
);
