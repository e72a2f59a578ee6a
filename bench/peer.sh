#!/usr/bin/env bash
# Run the Taichi peer benchmark of one 3D MLS-MPM substep (../shared/peer,
# see its README.md and RESULTS.md) and print its result line:
#
#   bench/peer.sh --particles 262144 --grid 64 --steps 30 --dtype f32 [--threads 1]
#
# prints on stdout (diagnostics on stderr):
#   taichi particles=P grid=G^3 steps=S dtype=D sec_per_step=X particle_steps_per_s=Y compile_s=Z
#
# Every argument goes to taichi_mpm3d_bench.py unchanged (--help lists them).
#
# Environment:
#   PEER_DIR      the peer scripts (default: ../shared/peer next to the repo); read-only is fine
#   PEER_VENV     the Python virtualenv (default: /work/peer-venv, outside the repo); created
#                 from $PEER_DIR/requirements.txt when missing (taichi only if the rest fails)
#   PEER_PYTHON   the interpreter that creates the venv (default: python3)
#   PEER_SCRATCH  where the scripts are copied to and run from, so that taichi's kernel cache
#                 (.cache/taichi, used with --offline-cache) and __pycache__ land there
#                 (default: target/peer in the repo)
set -euo pipefail

repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
peer_dir="${PEER_DIR:-$repo/../shared/peer}"
venv="${PEER_VENV:-/work/peer-venv}"
python="${PEER_PYTHON:-python3}"
scratch="${PEER_SCRATCH:-$repo/target/peer}"

log() { echo "peer.sh: $*" >&2; }

[[ -f "$peer_dir/taichi_mpm3d_bench.py" ]] || { log "no taichi_mpm3d_bench.py in $peer_dir (set PEER_DIR)"; exit 2; }
peer_dir="$(cd "$peer_dir" && pwd)"

have_taichi() {
    [[ -x "$venv/bin/python" ]] &&
        "$venv/bin/python" -c 'import importlib.metadata as m; m.version("taichi"); m.version("numpy")' >/dev/null 2>&1
}

create_venv() {
    log "creating the peer venv in $venv (taichi from $peer_dir/requirements.txt; takes a few minutes)"
    mkdir -p "$(dirname "$venv")"
    [[ -x "$venv/bin/python" ]] || "$python" -m venv "$venv"
    if ! "$venv/bin/pip" install --disable-pip-version-check -q -r "$peer_dir/requirements.txt" >&2; then
        # JAX is optional here: fall back to the pinned taichi and its dependencies
        log "full requirements failed; installing taichi only"
        grep -Ev '^(jax|jaxlib|ml_dtypes|opt_einsum|scipy)([=<>~!; ]|$)' "$peer_dir/requirements.txt" >"$venv/taichi-requirements.txt"
        "$venv/bin/pip" install --disable-pip-version-check -q -r "$venv/taichi-requirements.txt" >&2
    fi
}

if ! have_taichi; then
    # serialise concurrent first runs (two benches started at once)
    mkdir -p "$(dirname "$venv")"
    exec 9>"$venv.lock"
    command -v flock >/dev/null && flock 9
    have_taichi || create_venv
    have_taichi || { log "taichi is not importable from $venv after installing"; exit 1; }
    exec 9>&-
fi

# $PEER_DIR may be read-only, and the bench keeps taichi's cache next to itself:
# run a copy in the scratch folder
mkdir -p "$scratch"
for f in "$peer_dir"/*.py; do
    install -m 644 "$f" "$scratch/"
done

cd "$scratch"
# taichi must not phone home or write to $HOME (the bench sets this too)
export TI_SKIP_VERSION_CHECK=ON
status=0
out="$("$venv/bin/python" taichi_mpm3d_bench.py "$@")" || status=$?
# stdout: the result line only; taichi's banner and anything else go to stderr
grep -v '^taichi ' <<<"$out" | grep -v '^$' >&2 || true
grep '^taichi ' <<<"$out" || {
    [[ $status -ne 0 ]] || case " $* " in *" -h "* | *" --help "*) exit 0 ;; esac
    log "no result line from taichi_mpm3d_bench.py (exit $status)"
    exit $((status ? status : 1))
}
exit "$status"
