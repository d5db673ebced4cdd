// SPIR-V (Vulkan flavour) -> WGSL with naga compiled to WebAssembly (npm `naga-wasm`, pinned in
// the repository's package.json; `bash scripts/setup.sh` installs it into node_modules/).
//
// usage: node naga_wgsl.mjs [in.spv]              the WGSL on stdout (no argument: SPIR-V on
//                                                 stdin), parsed back and validated; on failure
//                                                 exit status 1, naga's report on stderr
//        node naga_wgsl.mjs --json a.spv b.spv    one JSON array on stdout, per file in order
//                                                 {"wgsl": text} (tidied, parsed back and
//                                                 validated) or {"error": naga's report}
//        node naga_wgsl.mjs --check a.wgsl b.wgsl one JSON array, per file {} or {"error": ...}:
//                                                 each WGSL file parsed and validated
//        node naga_wgsl.mjs --version             naga's version
//
// A translation reads the SPIR-V (parseSpirv), validates the module, writes WGSL, tidies it
// (tidy) and parses the text back (parseWgsl) to validate it, so a file that passes is one a
// WebGPU implementation built on naga accepts; a check does the last step alone. One process takes many files: Node's start-up costs more than a file.
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

// naga's WGSL made readable and portable: each function named after glslang's mangled name
// (`spec_float_u0028_f1_u003b`, `(` written `_u0028_`) given its plain name (numbered where
// taken: overloads); each override's default a plain literal (`= 37;`, not `37i`: the declared
// type gives the type); a fragment shader opened with `diagnostic(off, derivative_uniformity);`
// (browsers' compilers refuse implicit derivatives in loops whose exit depends on a texture)
const DERIVATIVES_DIRECTIVE = "diagnostic(off, derivative_uniformity);";
function tidy(wgsl) {
  const taken = new Set(wgsl.match(/\b\w+\b/g) ?? []);
  const renames = new Map();
  for (const mangled of [...taken].filter((n) => n.includes("_u0028_")).sort()) {
    const name = mangled.split("_u0028_")[0];
    let plain = name;
    for (let k = 1; taken.has(plain); k++) plain = `${name}_${k}`;
    taken.add(plain);
    renames.set(mangled, plain);
  }
  let out = wgsl.replace(/\b\w+\b/g, (w) => renames.get(w) ?? w);
  out = out.replace(/^(@id\(\d+\) override \w+: \w+ = -?[\d.]+(?:e[-+]?\d+)?)[fiu]?;$/gm, "$1;");
  return /^@fragment\b/m.test(out) ? `${DERIVATIVES_DIRECTIVE}\n\n${out}` : out;
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

// {wgsl} or {error} for one SPIR-V binary: read, validated, written, tidied, parsed back and
// validated again
function translate(bytes) {
  let wgsl;
  try {
    const module = naga.parseSpirv(new Uint8Array(bytes));
    wgsl = tidy(naga.writeWgsl(module, naga.validate(module)));
  } catch (e) {
    return { error: report("reading the SPIR-V and writing WGSL", e) };
  }
  const checked = check(wgsl);
  return checked.error === undefined ? { wgsl } : checked;
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
  const res = translate(fs.readFileSync(args.length ? args[0] : 0));
  if (res.error !== undefined) {
    process.stderr.write(`${res.error}\n`);
    process.exit(1);
  }
  process.stdout.write(res.wgsl);
}
