#!/usr/bin/env bash
# drender compare on the bundled Cornell box at a tiny size: the output
# directory and its schema (results.csv columns, results.json keys, report.md,
# plots), errors that fall as spp grows (statistical, with a margin; never a
# timing), the reference's own error reported, the same table from the same
# seed, --repeat, a reference file reused, --sampler as a list (the sampler a
# column of every output, per-parameter efficiency), --medium-grad as a list
# (a homogeneous medium, thin and thick: DRT's gain paths against the
# collisions), --primal cross (prb and
# tape agree, estimates unbiased, its reference apart from the shared
# primal's), and bad inputs refused before any work (exit 2, nothing written).
# Run by tests/run.sh (env: DRENDER = the binary); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup compare
require_drender
red=/materials/red/pbrMetallicRoughness/baseColorFactor
green=/materials/green/pbrMetallicRoughness/baseColorFactor
tiny="--res 12x12 --max-depth 4"

# py FILE EXPR: python3 over d = the JSON object in FILE (and rows = the CSV's rows)
py() {
    python3 - "$@" <<'EOF' || fail "check failed: $2"
import csv, json, math, os, sys
path, expr = sys.argv[1], sys.argv[2]
d = json.load(open(os.path.join(path, "results.json")))
rows = list(csv.DictReader(open(os.path.join(path, "results.csv"))))
if not eval(expr, {"d": d, "rows": rows, "math": math}):
    print(json.dumps({k: d[k] for k in ("reference", "skipped")}, indent=1), file=sys.stderr)
    for c in d["combinations"]:
        print(c["estimator"], c["sampling"], c["max_depth"], c["spp"], c["rel_error"], file=sys.stderr)
    sys.exit(1)
EOF
}

# ---- help, and what the registry offers (never a hard-coded list) ----
run --help
expect_rc 0 "drender --help"
grep -Eq '^ +compare +[^ ]' "$tmp/out" || fail "drender --help: compare not listed"
run compare --help
expect_rc 0 "compare --help"
for o in --estimators --sampling --spp --max-depth --reference --repeat --batches --target --primal --json; do
    expect_in out "$o" "compare --help lists $o"
done
# "available now: prb (detached),\n   tape (detached)" (one estimator a line,
# up to the next option) -> estimator:mode pairs
avail=$(sed -n '/available now: /,/^ *--spp /p' "$tmp/out" | sed '$d; s/.*available now: //' | tr -s ' \n' ' ')
[ -n "$avail" ] || fail "compare --help: no 'available now:' line"
n_pairs=$(python3 -c '
import re, sys
print(sum(len(m.split(", ")) for m in re.findall(r"\(([^)]*)\)", sys.argv[1]) if m != "none"))' "$avail")

# ---- forward mode: schema, falling errors, the reference's own error ----
run compare $tiny --param "$red" --spp 1,16 --reference spp:256 -o out1
expect_rc 0 "compare (forward)"
for f in results.csv results.json report.md reference.txt plots.gp error_vs_time.png memory_vs_depth.png efficiency.png; do
    [ -s "out1/$f" ] || fail "compare: out1/$f missing or empty"
done
for f in error_vs_time.png memory_vs_depth.png efficiency.png; do
    [ "$(head -c 4 "out1/$f" | tail -c 3)" = PNG ] || fail "out1/$f is not a PNG"
done
want='scene,mode,estimator,sampling,max_depth,spp,repeat,batches,seconds,rays,memory_bytes,record_bytes,invalid_samples,rel_error,rel_variance,efficiency,reference,reference_rel_se,sampler,medium_grad'
[ "$(head -1 out1/results.csv)" = "$want" ] || fail "results.csv header: $(head -1 out1/results.csv)"
# every pair the registry supports, at each spp, but the modes that would
# run as detached on a colour (left out, and said so); one CSV row per run
twins="['attached', 'mis', 'derivative-roughness']"
n_twins=$(python3 -c '
import re, sys
print(sum(m in ("attached", "mis", "derivative-roughness") for l in re.findall(r"\(([^)]*)\)", sys.argv[1]) for m in l.split(", ")))' "$avail")
py out1 "d['as_detached'] == $twins"
py out1 "len(d['combinations']) == 2 * ($n_pairs - $n_twins) and len(rows) == 2 * ($n_pairs - $n_twins)"
expect_in out "left out: attached,mis,derivative-roughness (they would run as detached sampling" "compare (forward)"
grep -q 'Left out of the default modes.*attached, mis, derivative-roughness' out1/report.md ||
    fail "report.md: the modes left out as detached"
# named, they run (as detached: the same random numbers, the same numbers)
run compare $tiny --param "$red" --spp 1 --batches 2 --estimators prb --sampling detached,attached -o named
expect_rc 0 "compare --sampling detached,attached (a colour)"
py named "d['as_detached'] == [] and [c['sampling'] for c in d['combinations']] == ['detached', 'attached']"
py named "d['combinations'][0]['parameters'][0]['value'] == d['combinations'][1]['parameters'][0]['value']"
py out1 "all(k in d for k in ('command', 'scene', 'mode', 'reference', 'combinations', 'rows', 'best', 'skipped'))"
py out1 "d['mode'] == 'forward' and d['reference']['kind'] == 'spp:256' and d['reference']['estimator']"
# the reference's own error is reported, finite and smaller than any run's
py out1 "0 < d['reference']['rel_se'] < min(c['rel_error'] for c in d['combinations'])"
py out1 "all(abs(float(r['reference_rel_se']) - d['reference']['rel_se']) <= 1e-5 * d['reference']['rel_se'] for r in rows)"
grep -q 'relative standard error' out1/report.md || fail "report.md does not state the reference's own error"
# errors fall as spp grows: 16x the samples should give ~1/4 the error; 0.7 leaves room for noise
py out1 "all(b['rel_error'] < 0.7 * a['rel_error'] for a in d['combinations'] for b in d['combinations']
          if a['estimator'] == b['estimator'] and a['sampling'] == b['sampling'] and a['spp'] == 1 and b['spp'] == 16)"
# the same random numbers: every estimator of one sampling mode gives the same gradient, to rounding
py out1 "all(abs(a['rel_error'] - b['rel_error']) <= 1e-6 * a['rel_error'] for a in d['combinations']
          for b in d['combinations'] if a['spp'] == b['spp'] and a['sampling'] == b['sampling'])"
py out1 "all(c['memory_bytes'] > 0 and c['rays'] > 0 and c['efficiency'] > 0 for c in d['combinations'])"
py out1 "all(len(c['parameters']) == 1 and c['parameters'][0]['summary'] == 'pixel_mean' for c in d['combinations'])"
# one sampler (the default): every row says so; one parameter: its efficiency is the run's
py out1 "d['samplers'] == ['independent'] and all(r['sampler'] == 'independent' for r in rows)"
py out1 "d['medium_grads'] == ['drt'] and all(r['medium_grad'] == 'drt' for r in rows)"
py out1 "all(abs(c['parameters'][0]['efficiency'] - c['efficiency']) <= 1e-9 * c['efficiency'] for c in d['combinations'])"
# what grad's default (--sampling auto) would run: detached for a colour; derivative-roughness, and why, for a small roughness
py out1 "d['auto_sampling'] == 'detached'"
grep -q 'would run \*\*detached\*\* sampling here\.' out1/report.md || fail "report.md: auto's choice for a colour"
gold_rough=/materials/rough-gold/pbrMetallicRoughness/roughnessFactor
run compare $tiny --param "$gold_rough" --set "$gold_rough=0.1" --spp 2 --batches 2 --estimators prb --sampling detached -o auto1
expect_rc 0 "compare of a roughness of 0.1"
py auto1 "d['auto_sampling'] == 'derivative-roughness'"
grep -q "would run \*\*derivative-roughness\*\* sampling here (/materials/rough-gold/pbrMetallicRoughness/roughnessFactor is 0.1, below 0.2)" \
    auto1/report.md || fail "report.md: auto's choice for a roughness of 0.1"

# ---- --sampler as a list: the sampler is a dimension of every output ----
run compare $tiny --param "$red" --param "$green" --spp 4,16 --sampler independent,stratified,sobol --estimators prb \
    --reference spp:256 -o smp
expect_rc 0 "compare --sampler independent,stratified,sobol"
py smp "d['samplers'] == ['independent', 'stratified', 'sobol'] and d['sampler'] == 'independent'"
# every sampling mode of prb x 3 samplers x 2 spp, in results.json and results.csv alike
# (less attached, mis and derivative-roughness, which run as detached on colours)
npb=$(python3 -c 'import re,sys; print(len(re.search(r"prb \(([^)]*)\)", sys.argv[1]).group(1).split(", ")) - 3)' "$avail")
py smp "len(d['combinations']) == 6 * $npb and len(rows) == 6 * $npb"
py smp "sorted(set(r['sampler'] for r in rows)) == ['independent', 'sobol', 'stratified']"
py smp "[r['sampler'] for r in rows] == [c['sampler'] for c in d['combinations']] == [r['sampler'] for r in d['rows']]"
# per parameter: an efficiency and a relative variance each, which add up to the run's variance
py smp "all(len(c['parameters']) == 2 and all(p['efficiency'] > 0 for p in c['parameters']) for c in d['combinations'])"
py smp "all(min(p['rel_variance'] for p in c['parameters']) < c['rel_variance'] for c in d['combinations'])"
# the samplers draw other numbers: at the same spp, their errors differ
py smp "len(set(c['rel_error'] for c in d['combinations'] if c['spp'] == 16 and c['sampling'] == 'detached')) == 3"
# stratified and Sobol numbers: below the independent error at 16 spp on this smooth derivative.
# Not for derivative sampling (either mode): its extra directions and their radiance paths draw
# from hashed sub-streams of the path's key (path_deriv.h), which no sampler
# stratifies, so at 12x12 and 16 spp its sobol error can land above independent's.
py smp "all(c['rel_error'] < next(i['rel_error'] for i in d['combinations'] if i['sampler'] == 'independent' and
        i['spp'] == 16 and i['sampling'] == c['sampling']) for c in d['combinations']
        if c['spp'] == 16 and c['sampler'] != 'independent' and not c['sampling'].startswith('derivative'))"
grep -q '^| estimator | sampling | sampler |' smp/report.md || fail "report.md: no sampler column"
grep -q 'prb detached sobol' smp/report.md || fail "report.md: the ranking does not name the sampler"
grep -q '^film filter=box crop=none sampler=independent,stratified,sobol$' smp/reference.txt ||
    fail "reference.txt does not record the sampler list"

# ---- --medium-grad as a list: the media derivative method is a dimension ----
# A homogeneous KHR medium (a 2 m cube). Thin (as in the file, least
# extinction 0.15: DRT's pilot finds few of its stretches collide and takes
# gain paths): the two methods give different numbers, both finite. Thick
# (extinction 3: DRT takes the gain at the path's collisions, as the
# baseline does): the same numbers to the bit. DRT's combinations say where
# the gain came from and why (medium_gain), the baseline's have none.
khr=$DR_TESTDIR/data/media/fog-khr.gltf
ext=/materials/0/extensions/DR_medium/extinction
for case in thin thick; do
    set_thick=()
    [ $case = thick ] && set_thick=(--set "$ext=3,3,3")
    run compare "$khr" --param "$ext" "${set_thick[@]}" --estimators prb --sampling detached --medium-grad drt,baseline \
        --spp 2,8 $tiny --batches 4 -o "mg_$case"
    expect_rc 0 "compare --medium-grad drt,baseline ($case)"
    py "mg_$case" "(d['medium_grads'] == ['drt', 'baseline'] and [c['medium_grad'] for c in d['combinations']] ==
                   ['drt', 'drt', 'baseline', 'baseline'] == [r['medium_grad'] for r in rows] and
                   d['reference']['kind'] == 'spp:128')"
    py "mg_$case" "all(math.isfinite(c['rel_error']) and c['rel_error'] > 0 for c in d['combinations'])"
    grep -q 'prb detached (media baseline)' "mg_$case/report.md" || fail "report.md ($case): no media method in the labels"
    grep -q '| detached (media drt) |' "mg_$case/report.md" || fail "report.md ($case): no media method in the table"
done
py mg_thin "d['combinations'][1]['parameters'][0]['value'] != d['combinations'][3]['parameters'][0]['value']"
py mg_thin "([(c['medium_gain'][0]['source'], c['medium_gain'][0]['reason']) for c in d['combinations'][:2]] ==
             [('gain_paths', 'pilot')] * 2 and all('medium_gain' not in c for c in d['combinations'][2:]))"
grep -qF "from gain paths (pilot: " mg_thin/report.md || fail "report.md (thin): DRT's gain source not named"
grep -qF "from the path's collisions (thick)" mg_thick/report.md || fail "report.md (thick): DRT's gain source not named"
py mg_thick "[c.get('medium_gain') for c in d['combinations']] == [[{'medium': '$ext'[:-len('/extinction')],
             'source': 'collisions', 'reason': 'thick'}]] * 2 + [None] * 2"
py mg_thick "(d['combinations'][1]['parameters'][0]['value'] == d['combinations'][3]['parameters'][0]['value'] and
             d['combinations'][1]['rel_error'] == d['combinations'][3]['rel_error'])"

# ---- the same seed gives the same table (timings aside); --repeat; reference files ----
# (out1's reference read back from its file: a forward-mode reference reused, and no second reference to compute)
run compare $tiny --param "$red" --spp 1,16 --reference out1/reference.txt --repeat 2 --json -o out2
expect_rc 0 "compare --repeat 2"
python3 -c 'import json,sys; json.load(open(sys.argv[1]))' "$tmp/out" || fail "--json: stdout is not one JSON object"
py out2 "len(rows) == 4 * ($n_pairs - $n_twins) and sorted(set(r['repeat'] for r in rows)) == ['0', '1']"
py out2 "all(c['seconds_min'] <= c['seconds_median'] <= c['seconds_max'] for c in d['combinations'])"
python3 - out1/results.csv out2/results.csv <<'EOF' || fail "the same seed gave a different table (out1 vs out2)"
import csv, sys
keys = ("estimator", "sampling", "max_depth", "spp", "rays", "memory_bytes", "rel_error", "rel_variance")
a = [tuple(r[k] for k in keys) for r in csv.DictReader(open(sys.argv[1]))]
b = [tuple(r[k] for k in keys) for r in csv.DictReader(open(sys.argv[2]))]
sys.exit(0 if a + a == b else 1)   # repeat 0 then repeat 1, both the same numbers
EOF

# ---- reverse mode, finite differences, and a reference file reused ----
run render $tiny --spp 64 -o target.exr
expect_rc 0 "render the target"
run compare $tiny --param "$red" --param "$green" --set "$red=0.4,0.3,0.3" --target target.exr \
    --estimators prb --sampling detached --spp 2,32 --reference fd:64 -o rev
expect_rc 0 "compare (reverse, fd reference)"
py rev "d['mode'] == 'reverse' and d['reference']['kind'] == 'fd:64' and d['reference']['eps'] == 0.01"
py rev "[len(p['value']) for p in d['combinations'][0]['parameters']] == [3, 3]"
py rev "d['combinations'][1]['rel_error'] < 0.7 * d['combinations'][0]['rel_error']"
run compare $tiny --param "$red" --param "$green" --set "$red=0.4,0.3,0.3" --target target.exr \
    --estimators prb --sampling detached --spp 2,32 --reference rev/reference.txt -o rev2
expect_rc 0 "compare --reference FILE"
py rev2 "d['reference']['file'].endswith('rev/reference.txt') and d['reference']['kind'] == 'fd:64'"
cmp <(cut -d, -f4-8,14,15,17,18 rev/results.csv) <(cut -d, -f4-8,14,15,17,18 rev2/results.csv) ||
    fail "the reference read back from its file gave other errors"

# ---- reverse mode with --primal cross: every run its own primal, as grad ----
run compare $tiny --param "$red" --param "$green" --set "$red=0.4,0.3,0.3" --target target.exr \
    --estimators prb,tape --sampling detached --sampler independent,sobol --spp 2,32 --primal cross -o cross
expect_rc 0 "compare --primal cross"
py rev "d['primal'] == 'shared'"
py cross "d['primal'] == 'cross' and d['mode'] == 'reverse' and d['reference']['kind'] == 'spp:512'"
grep -q "every run its own primal" cross/report.md || fail "report.md does not say the runs are their own primal"
grep -qx "primal_spp 0" cross/reference.txt || fail "reference.txt: a cross comparison has no shared primal"
# prb and tape run the same cross primal: the same gradients to rounding
# (the adjoints come from the paths, so a wiring that passed no cross loss
# to either would differ or fail)
python3 - cross/results.json <<'PY' || fail "compare --primal cross: prb and tape disagree"
import json, sys
c = json.load(open(sys.argv[1]))["combinations"]
key = lambda x: (x["sampler"], x["spp"])
prb = {key(x): x for x in c if x["estimator"] == "prb"}
tape = {key(x): x for x in c if x["estimator"] == "tape"}
assert prb.keys() == tape.keys() and len(prb) == 4, (prb.keys(), tape.keys())
for k in prb:
    for p, t in zip(prb[k]["parameters"], tape[k]["parameters"]):
        for a, b in zip(p["value"], t["value"]):
            assert abs(a - b) <= 1e-9 * max(abs(a), abs(b), 1e-12), (k, a, b)
PY
# unbiased: at 32 spp each red estimate is the loss's gradient (the finite
# differences of the shared run above, whose adjoint is at a 256 spp primal:
# 5 % for that difference) within 4 standard errors
python3 - cross/results.json rev/results.json <<'PY' || fail "compare --primal cross: estimates off the reference"
import json, sys
c = json.load(open(sys.argv[1]))["combinations"]
ref = json.load(open(sys.argv[2]))["combinations"][0]["parameters"][0]["reference"]
for x in c:
    if x["spp"] != 32:
        continue
    p = x["parameters"][0]
    for v, se, r in zip(p["value"], p["stderr"], ref):
        assert abs(v - r) <= 4 * se + 0.05 * abs(r), (x["estimator"], x["sampler"], v, se, r)
PY
# the default spp list without its 1 (the cross primal needs 2)
run compare $tiny --param "$red" --set "$red=0.4,0.3,0.3" --target target.exr --estimators prb --sampling detached \
    --batches 2 --primal cross -o cross_spp
expect_rc 0 "compare --primal cross (default --spp)"
py cross_spp "sorted(set(c['spp'] for c in d['combinations'])) == [4, 16, 64]"

# ---- refused before any work: exit 2, a message, nothing written ----
# --spp 1000000 makes any work that did start show up as a timeout (exit 124).
huge="--spp 1000000 --reference spp:1000000"
refused() {   # refused CODE "NEEDLES" ARGS...
    local code=$1 needles=$2
    shift 2
    last_cmd="drender $*"
    timeout 60 "$DRENDER" "$@" >"$tmp/out" 2>"$tmp/err" </dev/null
    rc=$?
    check_failed "$code" "$needles"
    [ ! -e bad ] || fail "$*: left bad/ behind"
}
refused 2 "unknown estimator 'nope'|prb" compare $tiny --param "$red" --estimators prb,nope $huge -o bad
refused 2 "unknown sampling mode 'sideways'" compare $tiny --param "$red" --sampling sideways $huge -o bad
refused 2 "--param is required" compare $tiny -o bad
refused 2 "-o DIR is required" compare $tiny --param "$red"
refused 2 "--spp: 4 is listed twice" compare $tiny --param "$red" --spp 4,4 -o bad
refused 2 "--sampler: unknown sampler 'halton'" compare $tiny --param "$red" --sampler sobol,halton $huge -o bad
refused 2 "--sampler: 'sobol' is listed twice" compare $tiny --param "$red" --sampler sobol,sobol $huge -o bad
refused 2 "--medium-grad: unknown method 'nulls'" compare $tiny --param "$red" --medium-grad drt,nulls $huge -o bad
refused 2 "--medium-grad: 'drt' is listed twice" compare $tiny --param "$red" --medium-grad drt,drt $huge -o bad
refused 2 "no --param is a participating medium's" compare $tiny --param "$red" --medium-grad drt,baseline $huge -o bad
# a sampling mode an estimator lacks, found from the registry via --help
lacking=$(python3 -c '
import re, sys
pairs = re.findall(r"(\w+) \(([^)]*)\)", sys.argv[1])
every = sorted({m for _, modes in pairs for m in modes.split(", ") if m != "none"})
for name, modes in pairs:
    for m in every:
        if m not in modes.split(", "):
            print(name, m); sys.exit(0)' "$avail")
if [ -n "$lacking" ]; then
    set -- $lacking
    refused 2 "estimator '$1' does not support $2" compare $tiny --param "$red" --estimators "$1" --sampling "$2" $huge -o bad
else
    echo "note: every estimator supports every sampling mode; the refusal of a missing pair is not exercised"
fi
refused 2 "made for parameters|/materials/2/pbrMetallicRoughness/baseColorFactor" compare $tiny --param "$red" --set "$red=0.4,0.3,0.3" --target target.exr \
    --spp 1000000 --reference rev/reference.txt -o bad
refused 2 "made for mode reverse" compare $tiny --param "$red" --param "$green" --spp 1000000 \
    --reference rev/reference.txt -o bad
refused 2 "other values" compare $tiny --param "$red" --param "$green" --target target.exr \
    --spp 1000000 --reference rev/reference.txt -o bad
# another scene: the same file with one byte more (its .bin and texture beside it)
cp "$DR_SCENES"/cornell-box.bin "$DR_SCENES"/cornell-box-checker.png .
{ cat "$DR_SCENES/cornell-box.gltf"; echo; } >other.gltf
refused 2 "made for scene|other.gltf" compare other.gltf $tiny --param "$red" --param "$green" --set "$red=0.4,0.3,0.3" \
    --target target.exr --spp 1000000 --reference rev/reference.txt -o bad
printf 'not a reference\n' >junk.txt
refused 3 "junk.txt|not a drender reference file" compare $tiny --param "$red" --spp 1000000 --reference junk.txt -o bad
refused 2 "/images/0|--reference spp:N" compare $tiny --param /images/0 --target target.exr --spp 1000000 \
    --reference fd -o bad
DRENDER_MEM_LIMIT=20M refused 2 "DRENDER_MEM_LIMIT|--max-depth" compare --param "$red" --res 512x512 --max-depth 64 \
    --spp 1000000 -o bad
# --filter, --crop and --sampler: a cropped run (full-frame target cut to the
# crop) writes its film into results.json; its reference errors are finite;
# a reference made for another film is refused; a crop outside the frame too
run compare $tiny --param "$red" --set "$red=0.4,0.3,0.3" --target target.exr --crop 2,3,8,6 \
    --filter gaussian:0.5 --sampler sobol --estimators prb --sampling detached --spp 2,8 -o film
[ "$rc" -eq 0 ] || fail "cropped compare: exit $rc"
python3 - film/results.json <<'PY' || fail "cropped compare: results.json"
import json, math, sys
d = json.load(open(sys.argv[1]))
assert d["crop"] == [2, 3, 8, 6] and d["filter"] == "gaussian:0.5" and d["sampler"] == "sobol", d
assert d["rows"] and all(math.isfinite(r["rel_error"]) for r in d["rows"]), d["rows"]
PY
grep -q "^film filter=gaussian:0.5 crop=2,3,8,6 sampler=sobol$" film/reference.txt || fail "reference.txt lacks the film"
refused 2 "made for the film|crop=2,3,8,6" compare $tiny --param "$red" --set "$red=0.4,0.3,0.3" --target target.exr \
    --spp 1000000 --reference film/reference.txt -o bad
refused 2 "--crop|12x12" compare $tiny --param "$red" --crop 8,8,8,8 --spp 1000000 -o bad
refused 2 "--primal: unknown mode 'halves'" compare $tiny --param "$red" --target target.exr --primal halves $huge -o bad
refused 2 "--primal is for reverse mode" compare $tiny --param "$red" --primal cross $huge -o bad
refused 2 "--spp 1|at least 2" compare $tiny --param "$red" --target target.exr --primal cross --spp 1,1000000 -o bad
refused 2 "stratified" compare $tiny --param "$red" --target target.exr --primal cross --sampler sobol,stratified \
    $huge -o bad
refused 2 "--reference fd|spp:N" compare $tiny --param "$red" --target target.exr --primal cross --spp 1000000 \
    --reference fd -o bad
refused 2 "--reference spp:1" compare $tiny --param "$red" --target target.exr --primal cross --spp 1000000 \
    --reference spp:1 -o bad
# a reference taken at the shared primal is another quantity
refused 2 "a primal of spp" compare $tiny --param "$red" --param "$green" --set "$red=0.4,0.3,0.3" --target target.exr \
    --primal cross --spp 1000000 --reference rev/reference.txt -o bad
echo "cli_compare: all checks passed"
