# Shell helpers shared by the benchmark scripts (sourced, not run).
# No dependency beyond bash, sed and awk.

# calc EXPR [FORMAT]: floating-point arithmetic through awk (default: 3 significant digits)
calc() { awk "BEGIN { printf \"${2:-%.3g}\", ($1) }"; }
yesno() { awk "BEGIN { print ($1) ? \"yes\" : \"no\" }"; }
truefalse() { awk "BEGIN { print ($1) ? \"true\" : \"false\" }"; }

# json_num JSON KEY [OBJECT]: the number stored under KEY (inside the flat
# sub-object OBJECT when given) of a single-line JSON object; empty if absent.
json_num() {
    local re
    if [[ -n ${3:-} ]]; then re="\"$3\": *{[^}]*\"$2\": *"; else re="\"$2\": *"; fi
    printf '%s\n' "$1" | sed -n "s/.*$re\([-+0-9.eE]*\).*/\1/p" | head -n 1
}

# median of the numbers given as arguments
median() { printf '%s\n' "$@" | sort -g | awk '{ v[NR] = $1 } END { print (NR % 2) ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2 }'; }

