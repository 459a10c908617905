// Validates a .glb with the Khronos glTF validator and prints its report as JSON on stdout.
// Usage: node validate.mjs FILE.glb
import { readFileSync } from "node:fs";
import { basename } from "node:path";
import validator from "gltf-validator";

const file = process.argv[2];
if (!file) {
    console.error("usage: node validate.mjs FILE.glb");
    process.exit(2);
}
const report = await validator.validateBytes(new Uint8Array(readFileSync(file)), {
    uri: basename(file),
    format: "glb",
    maxIssues: 0, // no limit: every issue is reported
    writeTimestamp: false,
});
process.stdout.write(JSON.stringify(report, null, 1) + "\n");
