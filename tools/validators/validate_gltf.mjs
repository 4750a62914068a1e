// Runs the Khronos glTF validator on every .glb/.gltf below a directory (or on given files)
// and prints one line per file with issues, then "files N errors E warnings W".
// Exit code 0 when there is no error, 1 otherwise, 2 on bad usage.
import { readFileSync, readdirSync, statSync } from 'node:fs';
import { join } from 'node:path';
import { createRequire } from 'node:module';

const require = createRequire(import.meta.url);
const validator = require('gltf-validator');

function listModels(path) {
  if (statSync(path).isFile()) return [path];
  const found = [];
  for (const entry of readdirSync(path, { withFileTypes: true })) {
    const full = join(path, entry.name);
    if (entry.isDirectory()) found.push(...listModels(full));
    else if (/\.(glb|gltf)$/i.test(entry.name)) found.push(full);
  }
  return found.sort();
}

const targets = process.argv.slice(2);
if (targets.length === 0) {
  console.error('usage: node validate_gltf.mjs DIR_OR_FILE...');
  process.exit(2);
}
let files = 0, errors = 0, warnings = 0;
for (const file of targets.flatMap(listModels)) {
  const report = await validator.validateBytes(new Uint8Array(readFileSync(file)), {
    uri: file,
    maxIssues: 100,
  });
  files += 1;
  errors += report.issues.numErrors;
  warnings += report.issues.numWarnings;
  if (report.issues.numErrors > 0 || report.issues.numWarnings > 0) {
    const messages = report.issues.messages
      .filter((m) => m.severity <= 1)
      .map((m) => `${m.severity === 0 ? 'error' : 'warning'} ${m.code} ${m.pointer ?? ''}: ${m.message}`);
    console.log(`${file}: ${messages.join('; ')}`);
  }
}
console.log(`files ${files} errors ${errors} warnings ${warnings}`);
process.exit(errors > 0 ? 1 : 0);
