# serve_port.sh - sourced by the serve tests. wait_port LOG PID prints the port that
# `isotouch serve` announced in LOG ("listening on 127.0.0.1:PORT"), waiting up to 30 s;
# nothing when it never did or PID ended first.
wait_port() {
  local log=$1 pid=$2 port=""
  for _ in $(seq 300); do
    port=$(sed -n 's/.*listening on 127\.0\.0\.1:\([0-9]*\).*/\1/p' "$log")
    [[ -n $port ]] && break
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.1
  done
  echo "$port"
}

# start_serve LOG ARG...: starts "$exe" serve ARG... in the background, its output in LOG;
# sets pid and port (wait_port's). Fails (status 1) when serve never said it was listening.
start_serve() {
  local log=$1; shift
  "$exe" serve "$@" >"$log" 2>&1 &
  pid=$!
  port=$(wait_port "$log" $pid)
  [[ -n $port ]]
}
