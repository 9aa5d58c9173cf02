#!/usr/bin/env python3
"""Check that two `study fit --out` model files agree: every fitted value of the second within the
standard errors of the two fits (the larger of the two), e.g. a campaign and its re-export.

    python3 tests/check_refit.py CLEAN_FIT.toml OTHER_FIT.toml

The fitted values and their standard errors are read from the header comment `study fit` writes
("# Fitted by ...: seal_friction.f_c = 6996.1 ± 2.8e0, ...").
"""
import re
import sys


def fitted(path):
    head = open(path).readline()
    if not head.startswith("# Fitted by"):
        sys.exit(f"{path}: no `# Fitted by` header: not written by `study fit --out`")
    found = re.findall(r"([a-z_0-9]+\.[a-z_0-9]+) = ([-+0-9.eE]+) ± ([-+0-9.eEinf]+)", head)
    if not found:
        sys.exit(f"{path}: no fitted values in its header")
    return {name: (float(v), float(se)) for name, v, se in found}


def main():
    a, b = fitted(sys.argv[1]), fitted(sys.argv[2])
    if a.keys() != b.keys():
        sys.exit(f"different parameters: {sorted(a)} vs {sorted(b)}")
    bad = 0
    for name in sorted(a):
        (va, sa), (vb, sb) = a[name], b[name]
        within = abs(va - vb) <= max(sa, sb)
        bad += not within
        print(f"  {name:<28} {va:.6g} ± {sa:.2g}  vs  {vb:.6g} ± {sb:.2g}  difference {abs(va - vb):.3g}: {'within' if within else 'OUTSIDE'} the standard errors")
    if bad:
        sys.exit(f"{bad} fitted value(s) differ by more than their standard errors")


if __name__ == "__main__":
    main()
