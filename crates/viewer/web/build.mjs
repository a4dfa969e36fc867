// Bundles the viewer page with esbuild: src/main.js (three.js, uPlot and our
// modules) into one main.js + main.css, and copies index.html beside them.
// Output folder: $VIEWER_OUT (crates/viewer/build.rs sets it to its OUT_DIR),
// else dist/ (for working on the page alone: `npm run build`).
import { build } from "esbuild";
import { copyFileSync, mkdirSync } from "node:fs";
import { join } from "node:path";

const out = process.env.VIEWER_OUT || "dist";
mkdirSync(out, { recursive: true });
await build({
  entryPoints: ["src/main.js"],
  bundle: true,
  minify: true,
  format: "esm",
  target: "es2020",
  outdir: out,
  legalComments: "linked",
  logLevel: "warning",
});
copyFileSync("src/index.html", join(out, "index.html"));
