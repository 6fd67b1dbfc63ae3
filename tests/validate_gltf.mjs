// Validates glTF / GLB files with the Khronos glTF validator (npm package
// gltf-validator), external resources (buffers, images) read from disk.
//
//   node tests/validate_gltf.mjs FILE...
//
// The package is looked up in $GLTF_VALIDATOR_DIR (default build/node, where
// tests/cli_gltf_validate.sh installs it: npm install --prefix build/node gltf-validator).
// Prints every issue (errors, warnings, infos, hints) per file; exits 1 if any
// file has errors or cannot be validated, 2 on usage errors.
import fs from 'node:fs';
import path from 'node:path';
import { createRequire } from 'node:module';

const files = process.argv.slice(2);
if (files.length === 0) {
    console.error('usage: node tests/validate_gltf.mjs FILE.gltf|FILE.glb...');
    process.exit(2);
}

const here = path.dirname(new URL(import.meta.url).pathname);
const prefix = path.resolve(process.env.GLTF_VALIDATOR_DIR || path.join(here, '..', 'build', 'node'));
let validator;
try {
    validator = createRequire(path.join(prefix, 'package.json'))('gltf-validator');
} catch (e) {
    console.error(`validate_gltf: cannot load gltf-validator from ${prefix}/node_modules ` +
                  `(npm install --prefix ${prefix} gltf-validator): ${e.message}`);
    process.exit(2);
}

const severityName = ['error', 'warning', 'info', 'hint'];
let failed = 0;
for (const file of files) {
    let bytes;
    try {
        bytes = new Uint8Array(fs.readFileSync(file));
    } catch (e) {
        console.error(`${file}: cannot read: ${e.message}`);
        failed++;
        continue;
    }
    const dir = path.dirname(path.resolve(file));
    let report;
    try {
        report = await validator.validateBytes(bytes, {
            uri: path.basename(file),
            maxIssues: 0,
            writeTimestamp: false,
            externalResourceFunction: (uri) => new Promise((resolve, reject) => {
                const p = path.resolve(dir, decodeURIComponent(uri));
                fs.readFile(p, (err, data) => err ? reject(err.toString()) : resolve(new Uint8Array(data)));
            }),
        });
    } catch (e) {
        console.error(`${file}: the validator failed: ${e}`);
        failed++;
        continue;
    }
    const is = report.issues;
    console.log(`${file}: ${is.numErrors} errors, ${is.numWarnings} warnings, ${is.numInfos} infos, ` +
                `${is.numHints} hints (gltf-validator ${report.validatorVersion})`);
    for (const m of is.messages)
        console.log(`  ${severityName[m.severity] || m.severity}: ${m.code}: ${m.pointer || ''}: ${m.message}`);
    if (is.numErrors > 0)
        failed++;
}
process.exit(failed ? 1 : 0);
