#!/usr/bin/env bash
# test_server_curl.sh KDRAYD CLIENTS_DIR — starts kdrayd on the default scene
# on a free loopback port and runs clients/curl-examples.sh against it; fails
# if any example fails or the daemon does not exit 0 on SIGTERM.
set -euo pipefail
KDRAYD=$1 CLIENTS=$2
LOG=$(mktemp)
SCENE_ARGS=()
[ -n "${KDRAY_TEST_SCENE:-}" ] && SCENE_ARGS=(--scene "default=$KDRAY_TEST_SCENE")
"$KDRAYD" --listen 127.0.0.1:0 "${SCENE_ARGS[@]}" 2>"$LOG" &
PID=$!
cleanup() { kill "$PID" 2>/dev/null || true; rm -f "$LOG"; }
trap cleanup EXIT
URL=
for _ in $(seq 3000); do  # up to 300 s: a sanitizer build on a busy box
  URL=$(grep -o 'listening on http://[0-9.:]*' "$LOG" | head -n1 | cut -d' ' -f3 || true)
  if [ -n "$URL" ] && curl -fsS -o /dev/null "$URL/v1/health" 2>/dev/null; then break; fi
  kill -0 "$PID" 2>/dev/null || { cat "$LOG"; echo "kdrayd died" >&2; exit 1; }
  sleep 0.1
done
"$CLIENTS/curl-examples.sh" "$URL" default
kill -TERM "$PID"
rc=0; wait "$PID" || rc=$?
trap - EXIT; rm -f "$LOG"
[ "$rc" -eq 0 ] || { echo "kdrayd exited $rc after SIGTERM" >&2; exit 1; }
echo "curl examples passed"
