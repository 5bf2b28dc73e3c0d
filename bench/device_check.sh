#!/usr/bin/env bash
# The checks a session lent an NVIDIA machine (the device tool) runs there, in one call:
#   the GL context tetvr makes, bench/methods.py (both methods, frames in turn, the first
#   views' images for bench/methods.py --accuracy here), then the GL tests.
# The machine has Python, numpy, scipy, pytest and xdist but nothing else of ours and no
# network; prepare here (bench/README.md, "On a lent GPU"):
#   .dev/whl   moderngl, glcontext, meshio wheels for its Python (cp312)
#   .dev/gl    Debian's libglvnd packages (libegl1 libgl1 libglvnd0 libopengl0 libglx0 ...)
#   .dev/data  ../shared/data;   .dev/cache  bench/corpus.py's cached tori
# and call: run(command="bash bench/device_check.sh", carry=[".dev"]).
# Environment: METHODS_S, TESTS_S (time limits, s), METHODS_ARGS (extra arguments to methods.py),
# FILTER_COMPARE=1 (methods.py again with the texture unit's filtering), TESTS_ARGS (to pytest),
# IMAGES=1 (the GL tests keep their images, $OUT/images.tgz: compare them with this machine's
# by bench/gpu_images.py; select tests with TESTS_ARGS, the download holds 16 MiB).
set -u
out=${OUT:-/tmp/device_check}
mkdir -p "$out"
if [ -d /usr/local/nvidia ]; then  # only there: unpacking into / would change this machine
  for f in .dev/gl/*.deb; do dpkg -x "$f" /; done
  ldconfig
  vendor=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
  [ -f "$vendor" ] && export __EGL_VENDOR_LIBRARY_FILENAMES=$vendor
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site \
    .dev/whl/*.whl || exit 1
  export PYTHONPATH=/tmp/site:$PWD
fi
export TETVR_SHARED_DATA=$PWD/.dev/data TETVR_BENCH_CACHE=$PWD/.dev/cache PYTHONUNBUFFERED=1
{
  nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv 2>&1
  nproc; python3 --version
  python3 -c "from tetvr.gl.context import create_context, describe; from tetvr.gl.filtering import probe_error
from tetvr.gl.interpolation import probe_interpolation
ctx = create_context(); print(describe(ctx)); print('linear filtering error (tetvr.gl.filtering):', probe_error(ctx))
print('interpolation error, pixels (tetvr.gl.interpolation):', probe_interpolation(ctx))"
} 2>&1 | tee "$out/check.log"
grep -q GL_RENDERER "$out/check.log" || { echo "no GL context: see above"; exit 1; }
# shellcheck disable=SC2086
timeout "${METHODS_S:-240}" python3 bench/methods.py --out "$out/methods" ${METHODS_ARGS:-} 2>&1 \
  | tee -a "$out/check.log"
if [ -n "${FILTER_COMPARE:-}" ]; then  # the same meshes with the texture unit's filtering, for its cost
  # shellcheck disable=SC2086
  TETVR_FILTER=texture timeout "${METHODS_S:-240}" python3 bench/methods.py --out "$out/methods_texture" \
    --image-size 64 ${METHODS_ARGS/--profile/} 2>&1 | grep -v "^ " | tee -a "$out/check.log"
fi
images=()
[ -n "${IMAGES:-}" ] && images=(-p bench.gpu_images) && export TETVR_TEST_IMAGES=/tmp/test_images
timeout "${TESTS_S:-150}" python3 -m pytest -m gl -p no:cacheprovider -n "$(nproc)" --timeout 120 -v \
  -o console_output_style=classic --tb=line "${images[@]}" ${TESTS_ARGS:-} tests >"$out/tests.log" 2>&1
echo "tests: exit $?"
[ -n "${IMAGES:-}" ] && tar czf "$out/images.tgz" -C /tmp test_images
grep -E "FAILED|ERROR" "$out/tests.log" | tail -40
tail -3 "$out/tests.log"
