#!/usr/bin/env python3
"""Check that two `study fit --out` model files agree: every fitted value of the second within two
standard errors (the larger of the two fits') of the first, e.g. a campaign and its re-export.

Two standard errors, as every other estimate in the tests is checked: one standard error fails a
third of the time by chance. The re-export CI checks (every 4th row, 256 Hz) holds a quarter of
the rows, so its standard errors are about twice the full file's, and the difference of the two
estimates has a standard error of about sqrt(se_b^2 - se_a^2). Measured (2026-11-30, the
tutorial, the remainder fitted per sample): f_s 10861 ± 322 N against 12052 ± 740 N (difference
1190, 1.8 standard errors of the difference); f_c 6996.1 ± 2.7 against 6993.5 ± 5.5.

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
        within = abs(va - vb) <= 2.0 * max(sa, sb)
        bad += not within
        print(f"  {name:<28} {va:.6g} ± {sa:.2g}  vs  {vb:.6g} ± {sb:.2g}  difference {abs(va - vb):.3g}: {'within' if within else 'OUTSIDE'} 2 standard errors")
    if bad:
        sys.exit(f"{bad} fitted value(s) differ by more than 2 standard errors")


if __name__ == "__main__":
    main()
