#!/usr/bin/env python3
"""Convert the AFM curves of AFM-analysis/afmformats (MIT) to softcontact's measurement table.

Run once by hand (needs `pip install afmformats==0.18.7 matplotlib`); its output is committed:

    python3 data/afm/convert.py SRC_DIR data/afm

SRC_DIR holds the files of afmformats' tests/data at commit 731b5ad8. Each curve becomes `<name>.csv`: t [s] from its first row kept,
x [nm] the tip's position along the pressing direction (x = -(height + F/k): the measured height
corrected for the cantilever's bend, so x grows as the tip presses into the sample) and f [nN] the
cantilever's force (f > 0 pushes). Blocks of samples are averaged so no curve has more than
MAX_ROWS rows; the block length is written in the file's header. A curve whose contact would keep fewer
than MIN_CONTACT_ROWS samples that way is cut instead to MAX_ROWS samples about the contact at the
instrument's rate (the header names the window).
"""
import os
import sys
import warnings

import afmformats
import numpy as np

MAX_ROWS = 3000
# Fewer contact samples than this after block averaging: the curve is cut to a window about the contact.
MIN_CONTACT_ROWS = 200
SOURCE = "https://github.com/AFM-analysis/afmformats"
COMMIT = "731b5ad88bbb99b2455694d29016acd85a731388"

# name: (file, curve index, what the file is)
CURVES = {
    "brain_creep": ("fmt-jpk-cc_pr14-brain-2021.06.30.jpk-force", 0,
                    "creep compliance (force clamp), brain tissue"),
    "polymergel_creep": ("fmt-jpk-cc_pr14-polymergel-2021.06.30.jpk-force", 0,
                         "creep compliance (force clamp), polymer gel"),
    "cell_relaxation": ("fmt-jpk-sr_cell1-0008.jpk-force", 0,
                        "stress relaxation (height clamp), cell"),
    "spot3_indentation": ("fmt-jpk-fd_spot3-0192.jpk-force", 0,
                          "approach and retract"),
    "flipsign_indentation": ("fmt-jpk-fd_flipsign_2015.05.22-15.31.49.352.jpk-force", 0,
                             "approach and retract"),
    "map_indentation": ("fmt-jpk-fd_map0d_extracted.jpk-force-map", 0,
                        "approach and retract, one point of a force map"),
    "reference_indentation": ("fmt-jpk-fd_map-data-reference-points.jpk-force-map", 0,
                              "approach and retract, one point of a force map"),
    "qi_stiff_indentation": ("fmt-jpk-fd_qi-data-2021.04.13.jpk-qi-series", 0,
                             "quantitative imaging, stiff cantilever"),
    "qi_adhesion": ("fmt-jpk-fd_2020.02.07-16.29.05.036.jpk-qi-data", 0,
                    "quantitative imaging, attractive tip"),
    "workshop_indentation": ("fmt-afm-workshop-fd_single_2018-08-01_13.06.09.csv", 0,
                             "approach and retract, AFM Workshop"),
}

# An AFM Workshop file holds the piezo's height and the deflection in volts, with no calibration and no
# time: afmformats' own tests read it with this calibration (a sensitivity of 10 nm/V, a 20 N/m
# cantilever), and its samples are stamped 1 ms apart here. The force's scale and the time are assumed,
# not the sample's.
ASSUMED = {"fmt-afm-workshop-fd_single_2018-08-01_13.06.09.csv": {"spring constant": 20.0, "sensitivity": 0.01e-6}}


def contact_span(force):
    """First and last sample more than 10 noise σ (at least 2 % of the range) above the free level of
    the curve's first fifth."""
    head = force[: max(20, len(force) // 5)]
    level = np.median(head)
    noise = np.std(np.diff(head)) / np.sqrt(2)
    above = np.nonzero(force - level > max(10 * noise, 0.02 * np.ptp(force)))[0]
    return (above[0], above[-1]) if len(above) else (0, len(force) - 1)


def blocks(values, length):
    n = len(values) // length * length
    return values[:n].reshape(-1, length).mean(axis=1)


def convert(src, name, file, index, what, out):
    curve = afmformats.load_data(os.path.join(src, file), meta_override=ASSUMED.get(file))[index]
    meta = curve.metadata
    k = float(meta["spring constant"])
    t = np.asarray(curve["time"], float) if "time" in curve.columns else np.arange(len(curve)) * 1e-3
    force = np.asarray(curve["force"], float)
    height = np.asarray(curve["height (measured)"], float)
    x = -(height + force / k)
    length = max(1, -(-len(t) // MAX_ROWS))
    first, last = contact_span(force)
    kept = ""
    if length > 1 and (last - first + 1) / length < MIN_CONTACT_ROWS:
        # A short contact averaged in blocks keeps too few samples of its loop: a window about it at the
        # instrument's own rate instead.
        lo = max(0, min(first - (MAX_ROWS - (last - first + 1)) // 2, len(t) - MAX_ROWS))
        hi = min(len(t), lo + MAX_ROWS)
        t, x, force = (v[lo:hi] for v in (t, x, force))
        kept = f"samples {lo}-{hi - 1} of {len(height)} (a window about the contact), none averaged"
        length = 1
    t, x, force = (blocks(v, length) for v in (t, x, force))
    t = t - t[0]
    path = os.path.join(out, name + ".csv")
    with open(path, "w") as f:
        f.write(f"# {what}\n")
        f.write(f"# source: {SOURCE} tests/data/{file} (commit {COMMIT}"
                + "), licence MIT, (c) 2019 Paul Müller\n")
        f.write(f"# instrument: {meta.get('instrument') or what.split(', ')[-1]}, recorded {meta.get('date')},"
                f" cantilever {k:.6g} N/m, modality {curve.modality}\n")
        if file in ASSUMED:
            f.write("# the file has no calibration and no time: sensitivity 10 nm/V and 20 N/m as afmformats' tests"
                    " assume them, 1 ms per sample; the force's scale and the time are not the sample's\n")
        f.write(f"# converted by data/afm/convert.py: x = -(height + F/k), {kept or f'blocks of {length} samples averaged'}\n")
        f.write("t [s],x [nm],f [nN]\n")
        for ti, xi, fi in zip(t, x, force):
            f.write(f"{ti:.6f},{xi * 1e9:.3f},{fi * 1e9:.5f}\n")
    return path, len(t)


def main():
    src, out = sys.argv[1], sys.argv[2]
    warnings.filterwarnings("ignore")
    for name, (file, index, what) in CURVES.items():
        path, rows = convert(src, name, file, index, what, out)
        print(f"{path}: {rows} rows")


if __name__ == "__main__":
    main()
