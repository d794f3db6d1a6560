#!/usr/bin/env bash
# What a newcomer meets on the command line of isotouch, isotouch-devemu and isotouch-sculpt
# (docs/exit-codes.md): usage errors exit 2 naming the option (never CLI11's 105/106), a bad
# file exits 1 naming it, --version prints "isotouch X.Y.Z" (CMake's project version) and
# exits 0, --help names a switch that defaults to on without "{false}", a number that is
# not finite gets one line saying what to give (no JSON parser text), and a window size
# that cannot be drawn is refused on the command line. None of it opens a window.
# Usage: cli_exit_codes.sh ISOTOUCH DEVEMU SCULPT|"" VERSION OUT
set -u
iso=$1 emu=$2 sculpt=$3 version=$4 out=$5
fail() { echo "FAIL: $*"; exit 1; }
rm -rf "$out"; mkdir -p "$out"

# expect NAME CODE REGEX CMD ARGS...: the exit code and a line of the output (stdout + stderr).
expect() {
  local name=$1 want=$2 regex=$3; shift 3
  "$@" > "$out/$name.log" 2>&1; local rc=$?
  [ "$rc" -eq "$want" ] || { cat "$out/$name.log"; fail "[$name] exit $rc, want $want"; }
  grep -Eq -- "$regex" "$out/$name.log" || { cat "$out/$name.log"; fail "[$name] output does not match '$regex'"; }
  echo "[$name] ok"
}

expect iso_unknown_option 2 "--bogus" "$iso" run --bogus
expect iso_bad_value 2 "--zoom: must be a finite number > 0, got 0" "$iso" render --zoom 0
expect iso_missing_arg 2 "file is required" "$iso" replay
expect iso_no_command 2 "A subcommand is required" "$iso"
expect iso_bad_file 1 "$out/missing.json" "$iso" run "$out/missing.json" --out "$out/o"
expect iso_version 0 "^isotouch $version\$" "$iso" --version
expect iso_help 0 "Exit status: 0 ok, 1 bad input or error, 2 usage error" "$iso" --help
expect emu_bad_value 2 "--rate" "$emu" --socket "$out/s.sock" --rate 0
expect emu_version 0 "^isotouch $version\$" "$emu" --version
expect emu_help 0 "--no-fifo" "$emu" --help
grep -q "{false}\|{true}" "$out/emu_help.log" && fail "isotouch-devemu --help shows a flag value: $(grep -m1 '{false}\|{true}' "$out/emu_help.log")"

if [ -n "$sculpt" ]; then
  expect sculpt_version 0 "^isotouch $version\$" "$sculpt" --version
  expect sculpt_help 0 "--no-sched-fifo" "$sculpt" --help
  grep -q "{false}\|{true}" "$out/sculpt_help.log" && fail "isotouch-sculpt --help shows a flag value: $(grep -m1 '{false}\|{true}' "$out/sculpt_help.log")"
  for v in nan inf 1e400; do
    expect "sculpt_iso_$v" 2 "^--iso: must be a finite number \(the isovalue in the volume's units.*got $v" \
      "$sculpt" "$out/v.mhd" --iso "$v"
    grep -qi "json" "$out/sculpt_iso_$v.log" && fail "--iso $v: JSON parser text reached the user"
  done
  expect sculpt_size 2 "--size: must be W \(height 3/4 of it\) or WxH .*got '8192': width 8192 outside 64 to 4096" "$sculpt" "$out/v.mhd" --iso 1 --size 8192
  # An empty size is refused, not taken as the default 1024x768.
  expect sculpt_size_empty 2 "--size: must be W \(height 3/4 of it\) or WxH .*got '': empty" "$sculpt" "$out/v.mhd" --iso 1 --size ""
  expect sculpt_size_empty_eq 2 "--size" "$sculpt" "$out/v.mhd" --iso 1 --size=
  expect sculpt_unknown_option 2 "--bogus" "$sculpt" "$out/v.mhd" --bogus
fi
echo "PASS cli exit codes"
