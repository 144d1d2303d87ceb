#!/usr/bin/env bash
# Regenerates the seed-000 figures of docs/methods.md ("Figures") from this folder's shots:
#   examples/figures/make_figures.sh [BUILD_DIR]     (default: build, from the repository root)
# Needs the Stanford bunny (../shared/data/bun_zipper.ply beside the repository) for all but the
# glory. Writes PNG previews to docs/images/ and scratch renders to $BUILD_DIR/figures/.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../.." && pwd)"
build="$(cd "${1:-$root/build}" && pwd)"
cloudbake="$build/tools/cloudbake/cloudbake"
work="$build/figures"
images="$root/docs/images"
[ -x "$cloudbake" ] || { echo "make_figures: $cloudbake not found; build first" >&2; exit 1; }
mkdir -p "$work"
render() {  # render SHOT OUT_NAME [extra args]: renders, copies the PNG of the first view
  local shot="$1" name="$2"; shift 2
  "$cloudbake" render "$shot" --out "$work/$name" --png --quiet "$@" >/dev/null
  local png
  png="$(ls "$work/$name"/*.png | head -n 1)"
  cp "$png" "$images/$name.png"
  echo "docs/images/$name.png"
}
# Variants of a shot: python3 rewrites keys into a copy next to the original (paths stay valid).
variant() {  # variant SHOT NEW_NAME PYTHON_STATEMENTS_ON_s
  local out="$here/.$2.json"
  python3 - "$1" "$out" "$3" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
exec(sys.argv[3])
json.dump(s, open(sys.argv[2], "w"))
PY
  echo "$out"
}
trap 'rm -f "$here"/.*.json' EXIT

render "$here/glory.json" glory
if [ ! -f "$root/../shared/data/bun_zipper.ply" ]; then
  echo "make_figures: $root/../shared/data/bun_zipper.ply is missing: the bunny figures need the shared data folder beside the repository" >&2
  exit 0
fi
render "$here/bunny_side.json" bunny_side
"$cloudbake" bake-slice "$work/bunny_side/bake.vdb" --grid mie_ratio --axis z --range 0,1 \
  --png "$images/bunny_mie_ratio.png" >/dev/null
echo "docs/images/bunny_mie_ratio.png"
render "$here/bunny_silver_lining.json" bunny_silver_lining
# Figure 9: the orders of scattering pass by pass (no geometric tail), small.
shot="$(variant "$here/bunny_side.json" "passes_0" "s['bake']={'method': 'single'}; s['lighting']['sky']['radiance']=[0, 0, 0]; s['views'][0]['resolution']=[192,144]; s['outputs']['vdb']=False")"
render "$shot" "bunny_passes_0" --png-exposure 3  # no multiple scattering: method single
for p in 1 2 4 16; do
  shot="$(variant "$here/bunny_side.json" "passes_$p" "s['bake'].update(passes=$p, tolerance=1e-6, tail=False); s['lighting']['sky']['radiance']=[0, 0, 0]; s['views'][0]['resolution']=[192,144]; s['outputs']['vdb']=False")"
  render "$shot" "bunny_passes_$p" --png-exposure 3
done
# Figure 10: one bake (same sun direction), three light colours, one fixed exposure.
declare -A sun=([day]="[3.0, 2.9, 2.7]" [sunset]="[3.0, 1.3, 0.45]" [night]="[0.25, 0.3, 0.55]")
declare -A sky=([day]="[0.12, 0.16, 0.25]" [sunset]="[0.2, 0.1, 0.08]" [night]="[0.01, 0.012, 0.03]")
for c in day sunset night; do
  shot="$(variant "$here/bunny_side.json" "colour_$c" "s['lighting']['sun']['irradiance']=${sun[$c]}; s['lighting']['sky']['radiance']=${sky[$c]}; s['views'][0]['resolution']=[192,144]; s['outputs']['vdb']=False")"
  render "$shot" "bunny_light_$c" --png-exposure 2.5
done
