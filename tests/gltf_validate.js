// Validates .glb files with the Khronos glTF validator (npm package gltf-validator); prints
// "FILE errors N warnings N" per file and exits 1 if any has an error. Used by test_cli.sh.
const validator = require('gltf-validator');
const fs = require('fs');
(async () => {
    let bad = 0;
    for (const f of process.argv.slice(2)) {
        const r = await validator.validateBytes(new Uint8Array(fs.readFileSync(f)));
        console.log(f, 'errors', r.issues.numErrors, 'warnings', r.issues.numWarnings);
        for (const m of r.issues.messages.slice(0, 5)) console.log('  ', m.code, m.message, m.pointer || '');
        if (r.issues.numErrors > 0) bad = 1;
    }
    process.exit(bad);
})();
