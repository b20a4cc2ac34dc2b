#!/usr/bin/env bash
# test_fetch_partial.sh FETCH MODELS — scenes/fetch refuses a partial ladder.
# A model tree holding only 2CylinderEngine lets scenes/fetch make the
# engine rungs but not the others: without --partial it must exit 1 and
# name the missing rungs (a ladder test on a machine without them would
# otherwise pass while testing less); with --partial it must exit 0 and
# still list engine in ladder.txt.
set -u
FETCH=$1 MODELS=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$tmp/models/glTF2/2CylinderEngine-glTF-Binary"
ln -s "$MODELS/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb" \
  "$tmp/models/glTF2/2CylinderEngine-glTF-Binary/"
fail=0
KDRAY_ASSIMP_MODELS=$tmp/models "$FETCH" "$tmp/out" >"$tmp/log" 2>&1
rc=$?
if [ $rc -ne 1 ]; then echo "FAIL: partial ladder exited $rc, want 1"; fail=1; fi
if ! grep -q 'ladder incomplete: .*haus' "$tmp/log"; then
  echo "FAIL: the missing rungs are not named:"; cat "$tmp/log"; fail=1
fi
KDRAY_ASSIMP_MODELS=$tmp/models "$FETCH" --partial "$tmp/out" >"$tmp/log2" 2>&1
rc=$?
if [ $rc -ne 0 ]; then echo "FAIL: --partial exited $rc, want 0"; cat "$tmp/log2"; fail=1; fi
if ! grep -q '^engine ' "$tmp/out/ladder.txt"; then echo "FAIL: no engine rung"; fail=1; fi
[ $fail = 0 ] && echo "ok: partial ladder refused, accepted with --partial"
exit $fail
