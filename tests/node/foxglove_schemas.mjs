#!/usr/bin/env node
// Writes the Foxglove well-known JSON schemas the executive's log uses, exactly as the official
// package exports them (@foxglove/schemas, pinned in package.json: dist/jsonschema), into
// executive/foxglove_schemas/NAME.json, which executive/log_topics.py loads at import.
// Run it after changing the pinned version; tests/planner/shore/test_foxglove_log.py checks
// that the vendored files equal the package's.
//
//   node tests/node/foxglove_schemas.mjs            write the files
//   node tests/node/foxglove_schemas.mjs --print    print {NAME: schema, ...} on stdout instead

import { mkdir, rename, writeFile } from "node:fs/promises";
import { createRequire } from "node:module";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";

const USED = ["LocationFix", "Log", "GeoJSON"]; // the log's foxglove.* topics (executive/log_topics.py)
const here = dirname(fileURLToPath(import.meta.url));
const schemas = createRequire(import.meta.url)("@foxglove/schemas/jsonschema");

const picked = Object.fromEntries(USED.map((name) => {
  if (!(name in schemas)) {
    process.stderr.write(`foxglove_schemas: @foxglove/schemas exports no ${name}\n`);
    process.exit(1);
  }
  return [name, schemas[name]];
}));

if (process.argv.includes("--print")) {
  process.stdout.write(JSON.stringify(picked) + "\n");
} else {
  const out = join(here, "..", "..", "executive", "foxglove_schemas");
  await mkdir(out, { recursive: true });
  for (const [name, schema] of Object.entries(picked)) {
    const path = join(out, `${name}.json`);
    await writeFile(`${path}.tmp`, JSON.stringify(schema, null, 2) + "\n");
    await rename(`${path}.tmp`, path); // atomic: a reader never sees half a file
    process.stdout.write(`wrote ${path}\n`);
  }
}
