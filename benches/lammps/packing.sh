# Sourced by run.sh, compare.sh, callgrind_compare.sh and scaling.sh: `lammps_packing N` makes
# work/dense_N.data, LAMMPS's dense packing of N discs (compressed from a gas: about 6 min for
# 10^5 on 2 cores), unless it is there, with $MPIRUN and $LMP where set (bundle.sh's carried
# build); `sdem_packing N SDEM` makes work/sdem_N/checkpoint.bin, the same discs as an sdem
# world (to_sdem.py and a 10-step run), and work/sdem_N_strips/checkpoint.bin, the same with the
# file's rows sorted into strips (`sdem sort-sample`), unless they are there. Both run in work/. `lammps_rate LOG N`
# prints the atom-steps per second of a LAMMPS log of N atoms (steps x N / its loop time).
lammps_packing() {
  local n=$1
  if [ ! -f dense_$n.data ]; then
    [ -f init_$n.data ] || python3 ../gen_init.py "$n" 54321 init_$n.data >/dev/null
    ${MPIRUN:-mpirun} --allow-run-as-root -np 2 "${LMP:-lmp}" -log log.compress_$n -screen none \
      -in in.compress -var tag "$n" -var phit 0.85 -var ncomp 20000 -var nrelax 20000
  fi
}
sdem_packing() {
  local n=$1 sdem=$2
  if [ ! -f sdem_$n/checkpoint.bin ]; then
    python3 ../to_sdem.py dense_$n.data sdem_$n 10 >/dev/null
    "$sdem" run sdem_$n.ron --out sdem_$n --quiet >/dev/null
  fi
  if [ ! -f sdem_${n}_strips/checkpoint.bin ]; then
    "$sdem" sort-sample sdem_${n}_grains.csv sdem_${n}_strips_grains.csv >/dev/null
    sed "s/sdem_${n}_grains.csv/sdem_${n}_strips_grains.csv/; s/name: \"sdem_$n\"/name: \"sdem_${n}_strips\"/" \
      sdem_$n.ron >sdem_${n}_strips.ron
    "$sdem" run sdem_${n}_strips.ron --out sdem_${n}_strips --quiet >/dev/null
  fi
}
lammps_rate() {
  awk -v n="$2" '/^Loop time/ {v = $9*n/$4} END {printf "%.4e", v}' "$1"
}
