// Validate one glTF file with the Khronos glTF validator (npm gltf-validator, installed by `make gltf-validator`
// into .cache/node) and print its report as JSON: node gltf_validate.js VALIDATOR_DIR FILE
const validator = require(process.argv[2]);
const bytes = new Uint8Array(require("fs").readFileSync(process.argv[3]));
validator.validateBytes(bytes, { maxIssues: 0 })
  .then((report) => console.log(JSON.stringify(report)))
  .catch((error) => { console.error(String(error)); process.exit(1); });
