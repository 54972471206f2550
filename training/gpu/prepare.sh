#!/usr/bin/env bash
# Run HERE (the developer machine), once per session that is lent a GPU, before training/gpu/run.sh:
# the device machine's image has PyTorch but none of this package's mesh and rendering
# dependencies, and it cannot download. This fetches them as CPython 3.12 x86-64 wheels into .whl/
# and the EGL / OpenGL loader packages into .gl/ (both ignored by git through .git/info/exclude;
# about 8 MB and 2 MB), which the run names in `carry`. See /work/.library/device/README.md.
set -euo pipefail
cd "$(git rev-parse --show-toplevel)"
grep -qx '/.whl/' .git/info/exclude || echo /.whl/ >> .git/info/exclude
grep -qx '/.gl/' .git/info/exclude || echo /.gl/ >> .git/info/exclude
rm -rf .whl && mkdir -p .whl
# the versions of this machine's .venv; deps already in the image (numpy, scipy, torch, matplotlib,
# pillow, pyyaml, tqdm, wrapt, typing-inspect, mypy-extensions, packaging) are not fetched
WHEELS="potpourri3d==1.4.0 robust_laplacian==1.1.0 trimesh==5.2.0 moderngl==5.13.0 glcontext==3.1.0
pygltflib==1.16.5 dataclasses-json==0.6.7 marshmallow==3.26.2 Deprecated==1.3.1
fast-simplification==0.2.0"
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
  --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 --platform manylinux_2_24_x86_64 \
  --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 --platform manylinux1_x86_64 \
  --platform manylinux_2_5_x86_64 -d .whl $WHEELS
rm -rf .gl && mkdir -p .gl /tmp/amd64/partial
o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
apt-get $o update -qq
(cd .gl && apt-get $o download -qq libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
ls -la .whl .gl
du -sh .whl .gl
