// node validate_gltf.cjs FILE: the Khronos glTF validator's report on FILE, as JSON on stdout.
// Run from the repository root (node_modules/gltf-validator, a devDependency).
const fs = require("fs");
const path = require("path");
const validator = require(path.resolve("node_modules/gltf-validator"));

const file = process.argv[2];
validator
  .validateBytes(new Uint8Array(fs.readFileSync(file)), { uri: path.basename(file), maxIssues: 0 })
  .then((report) => process.stdout.write(JSON.stringify(report)))
  .catch((error) => {
    process.stderr.write(String(error) + "\n");
    process.exit(1);
  });
