#!/usr/bin/env bash
# The mutation score of the kernel (docs/testing.md, "Mutation testing"): cargo-mutants over
# crates/kernel/src, every mutant tested by the kernel's own tests (its unit tests and
# crates/kernel/tests/peers.rs on every 10th case of the NumPy peers' fixtures and every effect's
# defaults: VSHAKE_PEERS_EVERY=10), built with the `mutants` profile (Cargo.toml: opt-level 0,
# incremental): about 2 minutes a mutant on 2 cores.
#
#   benches/mutants.sh                      # every mutant (about 3 550: 5 days on 2 cores;
#                                           #   --jobs J runs J at once where there are cores)
#   benches/mutants.sh --shard 0/100        # every 100th mutant: a sample across every file
#   benches/mutants.sh --in-diff my.diff    # the mutants on the lines a change touched
#   benches/mutants.sh --list               # what would be tested
#   benches/mutants.sh --random 24 --seed 1 # 24 mutants drawn at random from the list (shards of
#                                           #   one stride with neighbouring starts revisit the
#                                           #   same lines: docs/testing.md)
#
# Any other argument goes to cargo-mutants (`cargo install --locked cargo-mutants`). Results go to
# target/mutants-out/mutants.out (outcomes.json, caught.txt, missed.txt, unviable.txt, timeout.txt).
#
# The effects' modules are declared by the registry macro (`library!`), which cargo-mutants does
# not expand, so it would not find their files. The tree it mutates is a copy of this checkout's
# files (tracked and untracked, not ignored) in which effects/mod.rs also names every file of
# effects/ in a `#[cfg(any())]` module declaration: never compiled (the macro declares the real
# ones), but seen by cargo-mutants' walk of the module tree.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
command -v cargo-mutants >/dev/null || {
    echo "benches/mutants.sh: cargo-mutants not found; install it with: cargo install --locked cargo-mutants" >&2
    exit 2
}
copy=$(mktemp -d "${TMPDIR:-/tmp}/vshake-mutants.XXXXXX")
trap 'rm -rf "$copy" "$copy.list"' EXIT
# The files git knows or would add (not ignored), less those deleted in the work tree.
(cd "$root" && git ls-files -z --cached --others --exclude-standard |
    while IFS= read -r -d '' f; do if [ -e "$f" ]; then printf '%s\0' "$f"; fi; done |
    tar --null -T - -cf -) | tar -xf - -C "$copy"

effects="$copy/crates/kernel/src/effects"
{
    echo
    echo "// benches/mutants.sh: every effect file, for cargo-mutants' walk of the module tree."
    for f in "$effects"/*.rs; do
        name=$(basename "$f" .rs)
        [ "$name" = mod ] && continue
        grep -Eq "^(pub )?mod $name;" "$effects/mod.rs" && continue
        echo "#[cfg(any())]"
        echo "mod $name;"
    done
} >>"$effects/mod.rs"

export VSHAKE_PEERS_EVERY=${VSHAKE_PEERS_EVERY:-10}
mkdir -p "$root/target/mutants-out"
cd "$copy"

# --random N [--seed S]: N names drawn from the list (Python's random.sample, seed S, default 1),
# examined by one regex of the exact names (-F, matched against `--list`'s names) and written to
# target/mutants-out/random_selection.txt. cargo-mutants 27.1 applies no -F/-E filter to its
# "delete field ... from struct ... expression" mutants: the nine in effects/mod.rs (`Both`) come
# along with any selection; read them apart.
if [ "${1:-}" = --random ]; then
    count=${2:?"--random needs a count"}
    shift 2
    seed=1
    if [ "${1:-}" = --seed ]; then seed=${2:?"--seed needs a value"}; shift 2; fi
    cargo mutants --dir "$copy" --package vshake-kernel --list >"$copy.list"
    pattern=$(python3 - "$copy.list" "$count" "$seed" "$root/target/mutants-out/random_selection.txt" <<'PY'
import random, sys
names = [l.rstrip("\n") for l in open(sys.argv[1]) if l.strip()]
count, seed = int(sys.argv[2]), int(sys.argv[3])
if not 0 < count <= len(names):
    sys.exit(f"benches/mutants.sh: --random {count}: the list has {len(names)} mutants")
meta = set("\\.+*?()|[]{}^$#&-~")  # regex-syntax's meta characters, escaped
esc = lambda n: "".join("\\" + c if c in meta else c for c in n)
picked = random.Random(seed).sample(names, count)
open(sys.argv[4], "w").write("".join(n + "\n" for n in sorted(picked)))
print("^(?:" + "|".join(esc(n) for n in picked) + ")$")
PY
)
    set -- -F "$pattern" "$@"
fi
# Not `exec`: the trap removes the copy when cargo-mutants ends, whatever its status.
cargo mutants --dir "$copy" --profile mutants \
    --package vshake-kernel --test-package vshake-kernel \
    --output "$root/target/mutants-out" "$@"
