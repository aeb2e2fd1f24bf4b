// The Khronos glTF validator (npm gltf-validator) on one file: prints its report as JSON.
// Usage: VALIDATOR_DIR=<node_modules> node validate_gltf.mjs FILE.glb
import { createRequire } from "module";
import { readFileSync } from "fs";

const require = createRequire(process.env.VALIDATOR_DIR + "/");
const validator = require("gltf-validator");
const report = await validator.validateBytes(new Uint8Array(readFileSync(process.argv[2])), { maxIssues: 100 });
console.log(JSON.stringify(report.issues));
