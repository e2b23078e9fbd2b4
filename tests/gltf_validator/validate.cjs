// Validates each .glb named on the command line with the Khronos glTF validator and prints one
// JSON object: {path: {numErrors, numWarnings, numInfos, numHints, messages: [{code, severity,
// pointer, message}]}}. Run by tests/test_gltf.py; install with `npm ci --prefix tests/gltf_validator`.
"use strict";
const fs = require("fs");
const validator = require("gltf-validator");

async function main(paths) {
  const reports = {};
  for (const path of paths) {
    const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(path)),
                                                 { uri: path, maxIssues: 0 });
    reports[path] = { ...report.issues, messages: report.issues.messages };
  }
  process.stdout.write(JSON.stringify(reports));
}

main(process.argv.slice(2)).catch((error) => {
  process.stderr.write(String(error) + "\n");
  process.exit(2);
});
