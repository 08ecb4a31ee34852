#!/usr/bin/env bash
# Fails when a function in src/ is longer than 120 lines: a function that long is where review
# stalls, so it is split by meaning (named helpers, named structs for results). The count is
# clang-tidy's readability-function-size (LineThreshold): the line of the body's closing brace
# minus the line of its opening one, blanks and comments included. Run over every .cpp that git
# tracks under src/, and the headers under src/ they include, with the flags of a build
# folder's compile_commands.json.
#
# Usage: scripts/check_function_size.sh BUILD_DIR [FILE.cpp...]
#   BUILD_DIR  a configured build folder; CMake writes compile_commands.json when it configures
#              (CMAKE_EXPORT_COMPILE_COMMANDS), and nothing under src/ includes a file the
#              build generates, so no build is needed
#   FILE       check only these files (default: every src/**/*.cpp git tracks)
# Environment (all optional):
#   TESSERA_FUNCTION_LINES  the limit, default 120
#   TESSERA_TIDY_JOBS       clang-tidy processes at once, default $(nproc)
#   CLANG_TIDY              the clang-tidy binary, default clang-tidy (Debian's, 14)
#   TESSERA_FUNCTION_PREFILTER  a ctags span (lines) that sends a file to clang-tidy, default
#                           three quarters of the limit; 0 sends every file
#
# Output: one line per function over the limit, "file:line function N lines", sorted by file;
# exit status 1 when there is any. Exit status 2 when clang-tidy is missing, or cannot parse
# a file (its errors are printed): a file it cannot parse would otherwise pass unseen.
#
# Cost: clang-tidy parses each file as the compiler's front end does, seconds a file (the
# CLI's, which include CLI11, the most), so a universal-ctags prefilter (below) gives it only
# the files with a function near the limit: 10 of 208 today, about 30 s on 2 cores instead of
# about 4 min for every file.
#
# The CLI's subcommand files are compiled through one unity source (src/tools/CMakeLists.txt)
# and so have no entry of their own in compile_commands.json: clang-tidy then takes the flags
# of the nearest file in the same folder (its interpolation), a file of the same target. -w:
# compiler warnings are the build's business, and clang knows warnings GCC's flags do not.
set -uo pipefail

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$repo" || exit 2

if (($# < 1)); then
  echo "usage: $0 BUILD_DIR [FILE.cpp...]" >&2
  exit 2
fi
build=$1
shift
limit=${TESSERA_FUNCTION_LINES:-120}
jobs=${TESSERA_TIDY_JOBS:-$(nproc)}
tidy=${CLANG_TIDY:-clang-tidy}

if ! command -v "$tidy" >/dev/null 2>&1; then
  echo "check_function_size: $tidy not found (Debian: apt-get install clang-tidy;" \
    "scripts/install-deps.sh installs it)" >&2
  exit 2
fi
if [[ ! -f $build/compile_commands.json ]]; then
  echo "check_function_size: $build/compile_commands.json missing: configure that build" \
    "folder with CMake first" >&2
  exit 2
fi

files=("$@")
if ((${#files[@]} == 0)); then
  mapfile -t files < <(git ls-files -- 'src/*.cpp')
fi
if ((${#files[@]} == 0)); then
  echo "check_function_size: no files to check" >&2
  exit 2
fi

out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT

# The prefilter: universal-ctags lexes every file in a fraction of a second and lists each
# function definition from its name's line to its closing brace. That span is never shorter
# than clang-tidy's count (opening brace to closing brace), so only a file holding a span of
# at least $prefilter lines (a margin below the limit, for anything ctags reads differently)
# needs clang-tidy's parse, which costs seconds a file. A header with such a span is checked
# through a .cpp that includes it, or through every file when none does directly.
prefilter=${TESSERA_FUNCTION_PREFILTER:-$((limit * 3 / 4))}
if [[ $prefilter != 0 ]] && command -v ctags >/dev/null 2>&1 &&
    ctags --version 2>/dev/null | grep -q 'Universal Ctags'; then
  all=${#files[@]}
  mapfile -t candidates < <(printf '%s\n' "${files[@]}"; git ls-files -- 'src/*.h')
  mapfile -t long < <(printf '%s\n' "${candidates[@]}" |
    ctags --languages=C++ --kinds-C++=f --fields=+ne -x --_xformat='%{input}	%{line}	%{end}' -L - |
    awk -F'\t' -v n="$prefilter" '$3 != "" && $3 - $2 >= n { print $1 }' | sort -u)
  picked=()
  for f in "${long[@]}"; do
    if [[ $f != *.h ]]; then
      picked+=("$f")
      continue
    fi
    includer=$(grep -lE "^#include \"([a-z_/]*/)?$(basename "$f")\"" "${files[@]}" | head -1)
    if [[ -z $includer ]]; then
      picked=("${files[@]}")
      break
    fi
    picked+=("$includer")
  done
  mapfile -t files < <(((${#picked[@]})) && printf '%s\n' "${picked[@]}" | sort -u)
  echo "check_function_size: ctags finds ${#files[@]} of $all files with a function of" \
    "$prefilter lines or more; clang-tidy checks those"
  if ((${#files[@]} == 0)); then
    echo "check_function_size: $all files, limit $limit lines, no function near it"
    exit 0
  fi
fi

# One clang-tidy per file, its output in a file of its own so parallel runs never interleave.
config="{Checks: '-*,readability-function-size', CheckOptions: [
  {key: readability-function-size.LineThreshold, value: '$limit'}]}"
# Functions defined in headers under src/ count too (reported once, however many include them).
headers="^$repo/src/"
export tidy build config headers out
start=$SECONDS
printf '%s\0' "${files[@]}" | xargs -0 -P "$jobs" -n 1 sh -c '
  log="$out/$(printf %s "$1" | tr / _).log"
  "$tidy" -p "$build" --quiet --config="$config" --header-filter="$headers" --extra-arg=-w \
    "$1" >"$log" 2>&1
  echo "$?" >"$log.rc"' check
elapsed=$((SECONDS - start))

# A file clang-tidy could not parse: its compiler errors, then a non-zero status.
unparsed=()
for f in "${files[@]}"; do
  log="$out/$(printf %s "$f" | tr / _).log"
  if [[ ! -f $log.rc || $(cat "$log.rc") != 0 ]] || grep -q ': error: ' "$log"; then
    unparsed+=("$f")
    echo "check_function_size: clang-tidy could not parse $f:" >&2
    grep -E ': (error|fatal error): ' "$log" | head -20 >&2
  fi
done

# "path:line:col: warning: function 'name' exceeds ... [readability-function-size]", then
# "path:line:col: note: N lines including whitespace and comments (threshold 120)".
report=$(cat "$out"/*.log | awk -v root="$repo/" '
  /\[readability-function-size\]$/ {
    split($0, at, ":"); file = at[1]; line = at[2]
    sub("^" root, "", file)
    name = $0; sub(/^[^\x27]*\x27/, "", name); sub(/\x27.*$/, "", name)
    key = file ":" line
    names[key] = name
  }
  / note: [0-9]+ lines including whitespace and comments/ {
    split($0, at, ":"); file = at[1]; line = at[2]
    sub("^" root, "", file)
    n = $0; sub(/^.* note: /, "", n); sub(/ lines.*$/, "", n)
    lines[file ":" line] = n
  }
  END { for (key in lines) printf "%s %s %s lines\n", key, names[key], lines[key] }' |
  sort -t: -k1,1 -k2,2n -u)

if [[ -n $report ]]; then
  count=$(printf '%s\n' "$report" | wc -l)
  echo "check_function_size: $count functions over $limit lines (split them by meaning):"
  printf '%s\n' "$report" | sed 's/^/  /'
fi
echo "check_function_size: ${#files[@]} files, limit $limit lines, $jobs jobs, ${elapsed} s"
((${#unparsed[@]})) && exit 2
[[ -n $report ]] && exit 1
exit 0
