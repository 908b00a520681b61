// Validates JSON messages against lrfnet's JSON Schema files with ajv.
//   node validate_json.mjs SCHEMA_DIR MESSAGES_FILE
// MESSAGES_FILE: one message per line, "<schema file name>\t<JSON text>". Prints
// "validated N messages" and exits 0, or prints every failure (up to 20) and exits 1.
import fs from "node:fs";
import path from "node:path";
import { createRequire } from "node:module";

const Ajv = createRequire(import.meta.url)("ajv");

const [schemaDir, messagesFile] = process.argv.slice(2);
if (!schemaDir || !messagesFile) {
  console.error("usage: node validate_json.mjs SCHEMA_DIR MESSAGES_FILE");
  process.exit(2);
}
const ajv = new Ajv({ allErrors: true, strict: false });
const validators = new Map();
function validatorFor(name) {
  if (!validators.has(name)) {
    const schema = JSON.parse(fs.readFileSync(path.join(schemaDir, name), "utf8"));
    validators.set(name, ajv.compile(schema));
  }
  return validators.get(name);
}
let count = 0;
const failures = [];
for (const line of fs.readFileSync(messagesFile, "utf8").split("\n")) {
  if (!line) continue;
  const tab = line.indexOf("\t");
  const name = line.slice(0, tab);
  const text = line.slice(tab + 1);
  ++count;
  let message;
  try {
    message = JSON.parse(text);
  } catch (e) {
    failures.push(`${name}: not JSON: ${text.slice(0, 200)}`);
    continue;
  }
  const validate = validatorFor(name);
  if (!validate(message)) {
    failures.push(`${name}: ${ajv.errorsText(validate.errors)}: ${text.slice(0, 300)}`);
  }
}
if (failures.length > 0) {
  console.log(failures.slice(0, 20).join("\n"));
  console.log(`${failures.length} of ${count} messages invalid`);
  process.exit(1);
}
console.log(`validated ${count} messages`);
