#!/usr/bin/env bash
# Kill safety of drender optimize (issue 13): a run is SIGKILLed at random
# moments, about 20 times, each time continued with --resume (or started
# afresh when it died before its first checkpoint). After every kill the
# output directory must hold either no checkpoint (killed before the first)
# or a complete, valid one that --resume accepts, a loss.csv whose every line
# is whole, and no half-written progress image; at the end the result (the
# final checkpoint, loss.csv's losses, the -o glTF and its buffer) must equal
# an uninterrupted run's to the last digit (same --threads).
#
# Bounded: ~20 kills of a ~1 s run (16x16, 2 spp, depth 3), under a minute
# (120 s at most).
# DR_KILL_SEED=N repeats a sequence of kill times (printed on failure).
# Run by tests/run.sh (env: DRENDER, DR_TESTDIR); also runs alone.
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
data=$DR_TESTDIR/data/optimize
cli_setup optimize-kill
require_drender
seed=${DR_KILL_SEED:-$$}
RANDOM=$seed
kills_wanted=20

albedo=/materials/wall/pbrMetallicRoughness/baseColorFactor
"$DRENDER" render "$data/diffuse.gltf" -o target.exr --res 16x16 --spp 64 --max-depth 3 --seed 5 2>/dev/null ||
    fail "cannot render the target"
iters=60
common=("$data/diffuse.gltf" --target target.exr --param "$albedo" --set "$albedo=0.3,0.3,0.3" --spp 2
        --max-depth 3 --iters $iters --checkpoint-every 1 --render-every 7 --threads 2)

# ---- the uninterrupted run ----
t0=$EPOCHREALTIME
run optimize "${common[@]}" --out-dir ref -o ref/result.gltf
expect_rc 0 "uninterrupted run"
full_ms=$(awk -v a="$t0" -v b="$EPOCHREALTIME" 'BEGIN{printf "%d", (b - a) * 1000}')
[ -s ref/result.gltf ] && [ -s ref/checkpoint.txt ] || fail "the uninterrupted run wrote no result or checkpoint"

# check_dir: the state a kill may leave behind
check_dir() {   # check_dir WHEN
    local d=$dir when="seed $seed, $dir, $1"
    if [ -e $d/checkpoint.txt ]; then
        head -n 1 $d/checkpoint.txt | grep -qx 'drender-checkpoint 3' || fail "$when: checkpoint without its header"
        [ "$(tail -n 1 $d/checkpoint.txt)" = end ] || fail "$when: checkpoint does not end with 'end' (truncated)"
        local it
        it=$(sed -n 's/^iteration \([0-9]*\)$/\1/p' $d/checkpoint.txt)
        [ -n "$it" ] && [ "$it" -ge 1 ] && [ "$it" -le $iters ] || fail "$when: checkpoint iteration '$it'"
        # loss.csv is written before the checkpoint: it covers at least those iterations
        [ -s $d/loss.csv ] || fail "$when: a checkpoint at iteration $it but no loss.csv"
        [ "$(($(wc -l <$d/loss.csv) - 1))" -ge "$it" ] || fail "$when: loss.csv shorter than the checkpoint ($it)"
    fi
    if [ -e $d/loss.csv ]; then
        head -n 1 $d/loss.csv | grep -qx 'iteration,loss,seconds,parameter_error' || fail "$when: loss.csv header"
        tail -n +2 $d/loss.csv | grep -qvE '^[0-9]+,[-+0-9.eE]+,[0-9.]+,[-+0-9.eE]*$' &&
            fail "$when: loss.csv has a partial line: $(tail -n +2 $d/loss.csv | grep -vE '^[0-9]+,[-+0-9.eE]+,[0-9.]+,[-+0-9.eE]*$' | head -2)"
        [ "$(tail -c 1 $d/loss.csv | od -An -c | tr -d ' ')" = '\n' ] || fail "$when: loss.csv ends mid-line"
    fi
    # every progress image present is whole (PNG: ends with the IEND chunk)
    local f
    for f in $d/*.png; do
        [ -e "$f" ] || continue
        [ "$(tail -c 8 "$f" | od -An -tx1 | tr -d ' \n')" = 49454e44ae426082 ] || fail "$when: $f is not a whole PNG"
    done
    if [ -e $d/result.gltf ]; then
        python3 -c 'import json,sys; json.load(open(sys.argv[1]))' $d/result.gltf 2>/dev/null ||
            fail "$when: result.gltf is not whole JSON"
    fi
}

# ---- killed and resumed until it finishes ----
# One campaign: a fresh --out-dir, killed and resumed until a run completes;
# its result must equal the uninterrupted one. Campaigns repeat until about
# $kills_wanted kills in all (a resumed run has less left to do, so it often
# completes before it is killed again).
kills=0 starts=0 before_first=0 campaigns=0 t_start=$SECONDS
campaign() {
    dir=kill$campaigns
    local finished=false resume delay mine=0
    while ! $finished; do
        mine=$((mine + 1))
        resume=()
        [ -e $dir/checkpoint.txt ] && resume=(--resume)
        starts=$((starts + 1))
        # kill somewhere in [0, 1.1 x the whole run): often early (start-up,
        # first iterations, before.png), often mid-run, sometimes in the final writes
        delay=$(awk -v r=$RANDOM -v ms="$full_ms" 'BEGIN{printf "%.3f", (r / 32768.0) * 1.1 * ms / 1000}')
        # a machine much busier than when full_ms was measured can keep every
        # resumed run from reaching its next checkpoint: after 25 starts of one
        # campaign the run is left to finish (the result is still compared)
        [ $mine -le 25 ] || delay=3600
        last_cmd="drender optimize ... --out-dir $dir ${resume[*]} (killed after ${delay}s)"
        t_run=$EPOCHREALTIME
        "$DRENDER" optimize "${common[@]}" --out-dir $dir -o $dir/result.gltf "${resume[@]}" \
            >"$tmp/out" 2>"$tmp/err" </dev/null &
        bg_pid=$!
        if [ "$delay" = 3600 ]; then
            wait "$bg_pid"
            rc=$?
        else
            sleep "$delay"
            kill -KILL "$bg_pid" 2>/dev/null
            wait "$bg_pid" 2>/dev/null
            rc=$?
        fi
        bg_pid=
        if [ $rc -eq 137 ]; then
            kills=$((kills + 1))
            [ -e $dir/checkpoint.txt ] || before_first=$((before_first + 1))
        elif [ $rc -eq 0 ]; then   # it ended on its own before the signal
            finished=true
            # A fresh run that beat its kill shows the uninterrupted run was
            # timed on a busier machine: kill times are drawn from the faster
            # figure from now on, so later starts are not mostly kill-free
            # (CI under the sanitizers: 15 kills in 17 campaigns, 120 s).
            if [ ${#resume[@]} -eq 0 ]; then
                run_ms=$(awk -v a="$t_run" -v b="$EPOCHREALTIME" 'BEGIN{printf "%d", (b - a) * 1000}')
                [ "$run_ms" -lt "$full_ms" ] && full_ms=$run_ms
            fi
        else
            fail "seed $seed: a run between kills failed (exit $rc)"
        fi
        check_dir "after kill $kills (start $starts, ${delay}s)"
        [ $starts -le 200 ] || fail "seed $seed: no end after $starts starts"
    done

    # the same result as the uninterrupted run
    cmp -s ref/checkpoint.txt $dir/checkpoint.txt ||
        fail "seed $seed: $dir: final checkpoint differs: $(diff ref/checkpoint.txt $dir/checkpoint.txt | head -6)"
    cut -d, -f1,2 ref/loss.csv >"$tmp/lossA"
    cut -d, -f1,2 $dir/loss.csv >"$tmp/lossB"
    cmp -s "$tmp/lossA" "$tmp/lossB" || fail "seed $seed: $dir: loss.csv differs: $(diff "$tmp/lossA" "$tmp/lossB" | head -4)"
    cmp -s ref/result.gltf $dir/result.gltf || fail "seed $seed: $dir: result.gltf differs"
    local f
    for f in ref/*.bin; do
        cmp -s "$f" "$dir/${f#ref/}" || fail "seed $seed: $dir: ${f#ref/} differs"
    done
    # nothing half-written is left behind either (a killed run's temporaries
    # are removed by the next start)
    local leftovers
    leftovers=$(find $dir -name '*.tmp*' -o -name '.*tmp*' | head -5)
    [ -z "$leftovers" ] || fail "seed $seed: $dir: temporary files left in the output directory: $leftovers"
}
# The time bound keeps a slow machine (sanitizers, another job) from running
# for minutes: past 120 s no new campaign starts, and the test passes if it
# has checked at least $kills_min kills (every campaign's result was compared).
kills_min=8
while [ $kills -lt $kills_wanted ]; do
    if [ $((SECONDS - t_start)) -ge 120 ]; then
        [ $kills -ge $kills_min ] || fail "seed $seed: only $kills kills in 120 s (at least $kills_min needed)"
        echo "cli_optimize_kill: stopped at the 120 s bound with $kills of $kills_wanted kills"
        break
    fi
    campaigns=$((campaigns + 1))
    campaign
done
echo "cli_optimize_kill: $kills SIGKILLs ($before_first before the first checkpoint) in $starts starts," \
     "$campaigns campaigns (run ${full_ms} ms, seed $seed); every result identical to the uninterrupted run"
