#!/usr/bin/env bash
# The command of one call of the device tool (DEVELOPERS.md, "Running on a lent GPU"): on the
# lent machine, which has no Rust, installs the carried Vulkan loader (.gl) and rays.py's
# wheels (.whl), starts scripts/device-bench-parts.sh on the data folder that
# `scripts/device-bench.sh --pack DATA [BASE_REV]` made, in the background, and copies each
# part's results to $OUT as it finishes, until the parts are done or SECONDS have passed.
#   scripts/device-run.sh DATA [SECONDS] [SIZE] [DVR_SIZE]
# A later call within the machine's idle time runs the same command: the parts still running
# go on, and it copies what has finished since.
set -uo pipefail
cd "$(dirname "$0")/.."
d=${1:?data folder}; limit=${2:-560}; sizes=("${@:3}")
out=${OUT:?the device tool sets OUT}
res=/tmp/raystream-parts
if [ ! -d "$res" ]; then
  for f in .gl/*.deb; do dpkg -x "$f" /; done
  ldconfig
  python3 -m pip install -q --no-index --no-deps --target /tmp/site .whl/*.whl
  mkdir -p "$res"
  PYTHONPATH=/tmp/site setsid nohup bash scripts/device-bench-parts.sh "$d" "$res" "${sizes[@]}" \
    < /dev/null > "$res/parts.log" 2>&1 &
fi
while [ ! -f "$res/done" ] && [ $SECONDS -lt "$limit" ]; do sleep 5; done
# Finished parts (a part's folder is complete once the next part's log exists, or at done);
# the part still running comes back as far as it got, its log too.
cp -r "$res"/. "$out"/
ls "$res"
