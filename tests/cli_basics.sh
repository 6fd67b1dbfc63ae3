#!/usr/bin/env bash
# Command-line basics of drender: --version, --help, help COMMAND, usage
# errors. Run by tests/run.sh (env: DRENDER = the binary); also runs alone.
#
# Expected exit codes (cli/cli.h, man/drender.1):
#   0 = success (--version, --help, help, help render, render --help)
#   2 = usage error: no arguments, unknown command, unknown option,
#       option without its value
#   3 = input error (scene/image missing or malformed)  -- see cli_errors.sh
#   1 = other failures (cannot write output, ...)       -- see cli_errors.sh
set -u

# shellcheck source=SCRIPTDIR/lib/cli.sh
. "$(dirname "$0")/lib/cli.sh"
cli_setup basics
require_drender

# --version
run --version
expect_rc 0 "--version"
grep -Eqx 'drender [0-9]+\.[0-9]+\.[0-9]+' "$tmp/out" \
    || fail "--version: expected exactly one line 'drender X.Y.Z' on stdout"
[ "$(wc -l <"$tmp/out")" -eq 1 ] || fail "--version: expected one line"
expect_empty err "--version"

# --help and help: list every command on stdout
for args in "--help" "help"; do
    run $args
    expect_rc 0 "drender $args"
    expect_in out "usage: drender" "drender $args"
    for cmd in render help; do
        grep -Eq "^ +$cmd +[^ ]" "$tmp/out" || fail "drender $args: expected command '$cmd' listed with a summary"
    done
    expect_empty err "drender $args"
done

# every help text fits an 80-column terminal
for args in "--help" "render --help" "params --help" "grad --help" "fdcheck --help" "optimize --help" \
    "compare --help" "batch --help" "help --help"; do
    run $args
    expect_rc 0 "drender $args"
    long=$(awk 'length($0) > 80 { print length($0) ": " $0 }' "$tmp/out")
    [ -z "$long" ] || fail "drender $args: lines wider than 80 columns:
$long"
done

# help render and render --help: usage naming every option
for args in "help render" "render --help"; do
    run $args
    expect_rc 0 "drender $args"
    expect_in out "usage: drender render" "drender $args"
    for opt in -o --output --spp --max-depth --res --camera --seed --threads --json --help; do
        grep -qE -- "(^|[ ,])$opt([ ,=]|\$)" "$tmp/out" || fail "drender $args: expected option $opt in the usage"
    done
    expect_empty err "drender $args"
    cp "$tmp/out" "$tmp/usage.$rc.${args%% *}"
done
# both spellings print the same text
cmp -s "$tmp/usage.0.help" "$tmp/usage.0.render" || fail "'drender help render' and 'drender render --help' differ"
run help help
expect_rc 0 "drender help help"
expect_in out "usage: drender help" "drender help help"

# no arguments: usage on stderr, nothing on stdout, exit 2
run
expect_rc 2 "no arguments"
expect_in err "usage: drender" "no arguments (usage goes to stderr)"
expect_in err "render" "no arguments (usage lists the commands)"
expect_empty out "no arguments"

# unknown subcommand
run frobnicate
expect_rc 2 "unknown command"
expect_in err "frobnicate" "unknown command (message names it)"
expect_empty out "unknown command"
run help frobnicate
expect_rc 2 "help for an unknown command"
expect_in err "frobnicate" "help for an unknown command (message names it)"

# unknown options
run --bogus
expect_rc 2 "unknown global option"
expect_in err "'--bogus'" "unknown global option (message names it)"
run render --bogus
expect_rc 2 "unknown render option"
expect_in err "'--bogus'" "unknown render option (message names it)"
expect_empty out "unknown render option"
# inside a group of short options the message names the unknown letter
run render -xy
expect_rc 2 "unknown short render option"
expect_in err "'-x'" "unknown short render option in a group (message names it)"
# a flag given a value
run render --json=1
expect_rc 2 "flag with a value"
expect_in err "--json" "flag with a value (message names it)"

# options missing their value
for opt in --spp --res -o; do
    run render "$opt"
    expect_rc 2 "render $opt without a value"
    expect_in err "$opt" "render $opt without a value (message names the option)"
done

# usage errors are found before any work: nothing written
[ -z "$(ls -A)" ] || fail "usage errors left files behind: $(ls -A)"
echo "cli_basics: all passed"
