#!/usr/bin/env bash
# Packs what many_cores.sh needs on a machine that has neither LAMMPS nor a network (the lent
# 16-core machine of issue #16): a stripped release sdem, this machine's `lmp` with Open MPI and
# every library they load but the C library's own (relocated there with OPAL_PREFIX), and
# LAMMPS's 10^5-disc packing if work/ has it (compare.sh or scaling.sh build it, ~4-6 min on
# 2 cores). About 33 MB; x86-64 only, built against Debian 12's packages.
#   usage: benches/lammps/bundle.sh [DEST (default benches/lammps/work/bundle)]
# Needs `lmp` and `mpirun` here (apt-get install -y lammps openmpi-bin) and a release build.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
dest=$(realpath -m "${1:-$here/work/bundle}")
sdem=$here/../../target/release/sdem
[ -x "$sdem" ] || { echo "no release build: cargo build --release"; exit 1; }
command -v lmp >/dev/null || { echo "lmp not found: apt-get install -y lammps openmpi-bin"; exit 1; }
ompi_root=$(dirname "$(dirname "$(ompi_info --path pkglibdir | awk '{print $2}')")")   # .../openmpi
rm -rf "$dest" && mkdir -p "$dest"
strip -o "$dest/sdem" "$sdem"
stage=$(mktemp -d); p=$stage/ompi
mkdir -p "$p/bin" "$p/deps" "$p/lib/x86_64-linux-gnu"
cp "$(command -v lmp)" "$(command -v orted)" "$(realpath "$(command -v mpirun)")" "$p/bin/"
ln -sf "$(basename "$(realpath "$(command -v mpirun)")")" "$p/bin/mpirun"
# OPAL_PREFIX=P makes Open MPI look for its components under P/lib/x86_64-linux-gnu/openmpi and
# its help texts under P/share/openmpi, as Debian lays them out under /usr.
cp -a "$ompi_root" "$p/lib/x86_64-linux-gnu/"
rm -rf "$p/lib/x86_64-linux-gnu/openmpi/include"
mkdir -p "$p/share" && cp -a /usr/share/openmpi "$p/share/"
for f in "$p"/bin/* $(find "$p/lib" -name '*.so*' -type f); do ldd "$f" 2>/dev/null | awk '{print $3}' | grep '^/' || true; done |
  sort -u | grep -v -E '/(libc|libm|libpthread|libdl|librt|libresolv|libutil|ld-linux-x86-64)\.so' |
  grep -v '/openmpi/lib/' | while read -r lib; do cp -L "$lib" "$p/deps/"; done
tar -cJf "$dest/ompi.tar.xz" -C "$stage" ompi && rm -rf "$stage"
[ -f "$here/work/dense_100000.data" ] && xz -6 -T0 -c "$here/work/dense_100000.data" >"$dest/dense_100000.data.xz"
du -sh "$dest"/*
echo "carry $(realpath --relative-to="$here/../.." "$dest") and run: bash benches/lammps/many_cores.sh $(realpath --relative-to="$here/../.." "$dest")"
