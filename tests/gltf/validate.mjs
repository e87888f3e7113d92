// Validates .glb files with the Khronos glTF validator and prints one JSON object:
// {"file": {"errors": n, "warnings": n, "messages": [...first errors...]}}.
// usage: node validate.mjs FILE...
import { readFileSync } from "node:fs";
import validator from "gltf-validator";

const out = {};
for (const file of process.argv.slice(2)) {
  const report = await validator.validateBytes(new Uint8Array(readFileSync(file)), { maxIssues: 50 });
  out[file] = {
    errors: report.issues.numErrors,
    warnings: report.issues.numWarnings,
    messages: report.issues.messages.filter((m) => m.severity === 0).slice(0, 10).map((m) => `${m.code} ${m.pointer ?? ""}: ${m.message}`),
  };
}
console.log(JSON.stringify(out));
