// SPIR-V (Vulkan flavour) -> WGSL with naga compiled to WebAssembly (npm `naga-wasm`, pinned in
// the repository's package.json; `bash scripts/setup.sh` installs it into node_modules/).
//
// usage: node naga_wgsl.mjs [in.spv]              the WGSL on stdout (no argument: SPIR-V on
//                                                 stdin), parsed back and validated; on failure
//                                                 exit status 1, naga's report on stderr
//        node naga_wgsl.mjs --json a.spv b.spv    one JSON array on stdout, per file in order
//                                                 {"wgsl": text} or {"error": naga's report}
//        node naga_wgsl.mjs --check a.wgsl b.wgsl one JSON array, per file {} or {"error": ...}:
//                                                 each WGSL file parsed and validated
//        node naga_wgsl.mjs --version             naga's version
//
// A translation reads the SPIR-V (parseSpirv), validates the module and writes WGSL; a check
// parses WGSL (parseWgsl) and validates it, so a file that passes is one a WebGPU implementation
// built on naga accepts. One process takes many files: Node's start-up costs more than a file.
//
// The package is imported by name: Node resolves it from the node_modules/ folders above this
// file, so the script runs from any working directory.
import fs from "node:fs";

let naga;
try {
  naga = await import("naga-wasm");
} catch (e) {
  process.stderr.write(
    `cannot load the npm package naga-wasm (${e.message}); run \`bash scripts/setup.sh\` ` +
      "(npm ci) in the repository\n",
  );
  process.exit(2);
}

function report(step, e) {
  const text = e instanceof naga.NagaError ? `${e.kind}: ${e.formatted}` : String(e?.stack ?? e);
  return `naga ${naga.nagaVersion}, ${step}:\n${text}`;
}

// {wgsl} or {error} for one SPIR-V binary
function translate(bytes) {
  try {
    const module = naga.parseSpirv(new Uint8Array(bytes));
    return { wgsl: naga.writeWgsl(module, naga.validate(module)) };
  } catch (e) {
    return { error: report("reading the SPIR-V and writing WGSL", e) };
  }
}

// {} or {error} for one WGSL text
function check(text) {
  try {
    naga.validate(naga.parseWgsl(text));
    return {};
  } catch (e) {
    return { error: report("validating the WGSL", e) };
  }
}

const args = process.argv.slice(2);
if (args[0] === "--version") {
  process.stdout.write(`${naga.nagaVersion}\n`);
} else if (args[0] === "--json") {
  const out = args.slice(1).map((path) => translate(fs.readFileSync(path)));
  process.stdout.write(JSON.stringify(out));
} else if (args[0] === "--check") {
  const out = args.slice(1).map((path) => check(fs.readFileSync(path, "utf8")));
  process.stdout.write(JSON.stringify(out));
} else {
  let res = translate(fs.readFileSync(args.length ? args[0] : 0));
  res = res.error === undefined ? { ...res, ...check(res.wgsl) } : res;
  if (res.error !== undefined) {
    process.stderr.write(`${res.error}\n`);
    process.exit(1);
  }
  process.stdout.write(res.wgsl);
}
