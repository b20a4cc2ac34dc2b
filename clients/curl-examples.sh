#!/usr/bin/env bash
# curl-examples.sh — one curl call per kdray endpoint, runnable against a live
# daemon:  clients/curl-examples.sh [BASE_URL] [SCENE]
# (defaults http://127.0.0.1:8080 and "default"). Every call uses curl -fsS,
# so the script exits non-zero on the first failed request; the error example
# checks that the daemon answers a bad request with 400 problem+json.
set -euo pipefail
URL=${1:-http://127.0.0.1:8080}
SCENE=${2:-default}
J='Content-Type: application/json'
TMP=$(mktemp)
BODY=$(mktemp)
trap 'rm -f "$TMP" "$BODY"' EXIT
say() { printf '\n== %s\n' "$*"; }
# show CURL-ARGS...: the request must succeed; prints the answer's start.
show() { curl -fsS -o "$TMP" "$@"; head -c 600 "$TMP"; echo; }

say "health (alive?)"
curl -fsS "$URL/v1/health"

# Readiness, what a balancer or a Kubernetes readinessProbe asks: 200 and
# the executor's load while the daemon should get traffic; 503 problem+json
# while starting, shutting down or saturated (then with Retry-After), which
# curl -f turns into a failure here, as it would for a probe.
say "ready (take traffic?)"
curl -fsS -D "$TMP" "$URL/v1/ready"; echo
head -n 1 "$TMP"

say "metrics (first lines)"
curl -fsS -o "$TMP" "$URL/metrics"
head -n 5 "$TMP"

say "scenes"
show "$URL/v1/scenes"

say "one scene"
show "$URL/v1/scenes/$SCENE"

say "bundle, JSON: two rays from one origin, closest hit"
curl -fsS -H "$J" "$URL/v1/scenes/$SCENE/bundle" -d '{
  "origins": [0, 0, 10],
  "directions": [0, 0, -1,  0.1, 0.1, -1],
  "tmin": 0, "tmax": 1e30, "query": "closest"}'

# The same rays as base64 float32 (little-endian): origin (0,0,10) and the
# directions (0,0,-1), (0.1,0.1,-1); the answer comes back in base64 too.
say "bundle, base64 in and out"
curl -fsS -H "$J" "$URL/v1/scenes/$SCENE/bundle" -d '{
  "origins": {"f32": "AAAAAAAAAAAAACBB"},
  "directions": {"f32": "AAAAAAAAAAAAAIC/zczMPc3MzD0AAIC/"},
  "encoding": "base64"}'

say "bundle, any-hit (occlusion) with per-ray tmax"
curl -fsS -H "$J" "$URL/v1/scenes/$SCENE/bundle" -d '{
  "origins": [0, 0, 10,  0, 0, 10],
  "directions": [0, 0, -1,  0, 0, -1],
  "tmax": [0.5, 1e30], "query": "any"}'

say "cone-shadow: two points, one spherical light, with statistics"
curl -fsS -H "$J" "$URL/v1/scenes/$SCENE/cone-shadow" -d '{
  "points": [0, 0, 0,  0.5, 0, 0],
  "lights": [{"center": [100, 100, 100], "radius": 5}],
  "samples": 16, "seed": 1, "stats": true}'

say "frustum: a 16x8 image in 4x4 tiles"
show -H "$J" "$URL/v1/scenes/$SCENE/frustum" -d '{
  "camera": {"eye": [0, 0, 10], "target": [0, 0, 0], "up": [0, 1, 0],
             "fov_y_deg": 60, "width": 16, "height": 8},
  "tile": 4, "query": "closest", "encoding": "base64"}'

say "bundle, only the hit distances (\"fields\")"
curl -fsS -H "$J" "$URL/v1/scenes/$SCENE/bundle" -d '{
  "origins": [0, 0, 10], "directions": [0, 0, -1,  0.1, 0.1, -1], "fields": ["t"]}'

# A binary (CBOR, application/cbor) body from a file: the map
# {"origins": 85(h'...'), "directions": 85(h'...')} with float32 typed arrays
# (RFC 8746 tag 85, little-endian): origin (0,0,10), directions (0,0,-1) and
# (0.1,0.1,-1). The answer is CBOR too (typed arrays for t, prim, u, v);
# here its first bytes: a5 = a map of 5, 65 "count", 02 = 2, 61 "t", d8 55...
say "bundle, CBOR body from a file, CBOR answer"
printf '\xa2\x67origins\xd8\x55\x4c%b%b%b' \
  '\x00\x00\x00\x00' '\x00\x00\x00\x00' '\x00\x00\x20\x41' > "$BODY"
printf '\x6adirections\xd8\x55\x58\x18%b%b%b%b%b%b' \
  '\x00\x00\x00\x00' '\x00\x00\x00\x00' '\x00\x00\x80\xbf' \
  '\xcd\xcc\xcc\x3d' '\xcd\xcc\xcc\x3d' '\x00\x00\x80\xbf' >> "$BODY"
code=$(curl -fsS -o "$TMP" -w '%{http_code} %{content_type}' \
  -H 'Content-Type: application/cbor' --data-binary @"$BODY" \
  "$URL/v1/scenes/$SCENE/bundle")
echo "$code, $(wc -c < "$TMP") bytes:"
od -An -tx1 "$TMP" | head -n 3
case "$code" in
  "200 application/cbor") ;;
  *) echo "curl-examples: expected 200 application/cbor, got $code" >&2; exit 1 ;;
esac

say "the same CBOR body, answered in JSON (Accept)"
curl -fsS -H 'Content-Type: application/cbor' -H 'Accept: application/json' \
  --data-binary @"$BODY" "$URL/v1/scenes/$SCENE/bundle"
echo

say "a picture: render.png (no camera given: the daemon frames the scene)"
code=$(curl -fsS -o "$TMP" -w '%{http_code} %{content_type}' -D - \
  "$URL/v1/scenes/$SCENE/render.png?width=320&height=240&samples=16" | tr -d '\r' |
  grep -E '^(Server-Timing|X-Kdray-Render)|^[0-9]' || true)
echo "$code"
echo "$(wc -c < "$TMP") bytes of PNG"
head -c 8 "$TMP" | od -An -tx1 | grep -q '89 50 4e 47 0d 0a 1a 0a' ||
  { echo "curl-examples: render.png is not a PNG" >&2; exit 1; }

say "an error: a direction that is not a number is 400 problem+json"
code=$(curl -sS -o "$TMP" -w '%{http_code} %{content_type}' -H "$J" \
  "$URL/v1/scenes/$SCENE/bundle" -d '{"origins": [0,0,0], "directions": [0, 0, "x"]}')
cat "$TMP"; echo
echo "$code"
case "$code" in
  "400 application/problem+json"*) ;;
  *) echo "curl-examples: expected 400 problem+json, got $code" >&2; exit 1 ;;
esac
say "all examples answered"
