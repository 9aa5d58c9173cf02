"""Writes the MAT-file fixtures of tests/matlab.rs with SciPy's savemat (an implementation
independent of vshake's reader), and expected.csv: the same channels in SI.

    python3 -m venv /tmp/sp && /tmp/sp/bin/pip install scipy && /tmp/sp/bin/python make.py

A 2 Hz sine at 1000 Hz for 0.3 s: reference and table displacement, table acceleration.
"""
import os

import numpy as np
from scipy.io import savemat

here = os.path.dirname(os.path.abspath(__file__))
g = 9.80665
n, fs = 300, 1000.0
t = np.arange(n) / fs
w = 2 * np.pi * 2.0
ref = 0.01 * np.sin(w * t)
disp = 0.0099 * np.sin(w * t - 0.1)
accel = -w * w * disp

with open(os.path.join(here, "expected.csv"), "w") as f:
    f.write("time_s,ref_disp_m,disp_m,accel_mps2\n")
    for row in zip(t, ref, disp, accel):
        f.write(",".join(repr(float(v)) for v in row) + "\n")


def save(name, variables, compress, oned_as="column"):
    savemat(os.path.join(here, name), variables, format="5", do_compression=compress,
            oned_as=oned_as)


# MATLAB writetable-style names, SI, uncompressed (save -v6), with a scalar, text and a struct
# beside the channels.
save("v5_names.mat", {"Time": t, "RefDisp": ref, "Disp": disp, "Accel": accel, "fs": fs,
                      "operator": "lab", "meta": {"rate": fs, "units": "SI"}}, False)
# Compressed (save -v7): row vectors, units in the names, an int16 channel beside them.
save("v7_units.mat", {"t": t, "ref_disp_mm": ref * 1e3, "disp_mm": disp * 1e3,
                      "accel_g": accel / g, "counts": np.int16(np.round(disp * 1e5))},
     True, oned_as="row")
# One samples x channels matrix, as a DAQ saves its buffer: mapped by position.
save("v7_matrix.mat", {"data": np.column_stack([t, ref * 1e3, disp * 1e3, accel / g])}, True)
# Only a struct (what a MATLAB table or struct of channels gives): refused, saying what to save.
save("v7_struct.mat", {"test": {"t": t, "accel": accel}}, True)
# Channels of different lengths: refused, naming them.
save("v5_lengths.mat", {"t": t, "ref_disp": ref, "disp": disp, "accel": accel[:-1]}, False)
