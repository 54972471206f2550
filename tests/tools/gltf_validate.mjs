// Validate a .glb/.gltf file with the Khronos glTF validator (npm package gltf-validator).
// Usage: node gltf_validate.mjs FILE  -> prints the report's issues as JSON; exit 0.
import { readFileSync } from "node:fs";
import { createRequire } from "node:module";

const require = createRequire(process.env.GLTF_VALIDATOR_DIR + "/");
const validator = require("gltf-validator");
const file = process.argv[2];
const report = await validator.validateBytes(new Uint8Array(readFileSync(file)), {
  maxIssues: 100,
});
console.log(JSON.stringify(report.issues));
