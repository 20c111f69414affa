"""How far the library's effect forms can take a curve's in-contact residual when fitted in-sample.

An independent check of the discrepancy workflow's search on one curve, written without its code: the
base law f = f0 + k·zᵃ (the free level f0 fitted) and the effects of docs/discrepancy.md as linear
columns, each for a grid of its nonlinear parameter — a Maxwell branch driven by z (viscoelastic
relaxation) and one driven by zᵃ (quasi-linear relaxation), both stepped as the library steps them; the
medium's drag ż; a squeeze film reach/(gap + reach)·ż; an adhesion's share of its pull-off after the
deepest point; hysteresis zᵃ·tanh(ż/v₀) — with the surface and a on a grid (a ≤ 2.5, the library's
range). For every subset of the six effects it fits the whole curve by least squares (columns scaled,
so none is dropped as small), the surface itself on a grid from 200 nm before `--surface` (the surface
`softcontact discrepancy` prints) to 100 nm after it, and reports for each number of effects the subset
that fits the whole curve best, with its RMS over the samples the workflow counts as in contact (deeper
than `--surface`). In-sample: the parameters are chosen on the samples scored, so a held-out selection
of the same forms on the same grids should expect to do worse, not better.

The rate is the depth's local slope over `--rate-width` samples, 9 by default: the depth of the curves
kept at the instrument's 0.5 ms (flipsign, map, spot3) is too noisy for central differences, which
`softcontact identify` says. `--brush` adds a form the library does not have, an exponential layer
before the surface, F_b·exp(z/λ) (the steric brush of a cell's surface in AFM; a soft cover over a
stiffer body at a robot's scale). The base law has no damping term (the workflow's final law on
flipsign has λ = 0), so on curves whose law damps this is not a bound on the workflow.

    python3 data/afm/library_reach.py data/afm/flipsign_indentation.csv --surface=-1.871973510678394e-5

Needs numpy. Prints one line per number of effects: the best subset and its in-contact RMS.
"""

import argparse
import itertools

import numpy as np


def read(path):
    """t [s], x [m], f [N] of a table written by convert.py (t [s], x [nm], f [nN])."""
    with open(path, encoding="utf-8") as lines:
        rows = np.loadtxt([line for line in lines if not line.startswith("#")][1:], delimiter=",")
    return rows[:, 0], rows[:, 1] * 1e-9, rows[:, 2] * 1e-9


def local_slope(t, x, width=9):
    """dx/dt as the least-squares slope over `width` samples about each (fewer at the ends)."""
    half = width // 2
    out = np.empty_like(x)
    for i in range(len(x)):
        a, b = max(0, i - half), min(len(x), i + half + 1)
        tt = t[a:b] - t[a:b].mean()
        out[i] = (tt * (x[a:b] - x[a:b].mean())).sum() / (tt * tt).sum()
    return out


def branch(u, dt, tau):
    """A Maxwell branch of unit stiffness driven by u: s ← s·e^(−dt/τ) + Δu·τ(1 − e^(−dt/τ))/dt."""
    s = np.zeros_like(u)
    decay = np.exp(-dt / tau)
    gain = tau * (1.0 - decay) / dt
    for j in range(1, len(u)):
        s[j] = s[j - 1] * decay + (u[j] - u[j - 1]) * gain
    return s


def adhesion_share(z, peak_index, reach):
    """The library's adhesion share: min(1, (z_peak − z)/(z_peak + reach)) after the deepest point, 0 past −reach."""
    share = np.zeros_like(z)
    peak = z[peak_index]
    after = slice(peak_index, None)
    share[after] = np.clip((peak - z[after]) / (peak + reach), 0.0, 1.0)
    share[after][z[after] < -reach] = 0.0
    return share


EFFECTS = ("viscoelastic_relaxation", "quasi_linear_relaxation", "medium_drag", "squeeze_film", "adhesion",
           "hysteresis")
BRUSH = "brush (not of the library)"


def columns(t, x, rate, surface, a):
    """For each effect, its candidate columns (one per grid value) at one surface and exponent."""
    dt = float(np.median(np.diff(t)))
    peak_index = int(np.argmax(x))
    z = x - surface
    pressed = np.maximum(z, 0.0)
    gap = np.maximum(-z, 0.0)
    elastic = pressed**a
    return elastic, {
        "viscoelastic_relaxation": [branch(pressed, dt, tau) for tau in (3e-3, 1e-2, 3e-2, 0.1)],
        "quasi_linear_relaxation": [branch(elastic, dt, tau) for tau in (1e-3, 3e-3, 1e-2)],
        "medium_drag": [rate],
        "squeeze_film": [reach / (gap + reach) * rate for reach in (1e-7, 3e-7)],
        "adhesion": [-adhesion_share(z, peak_index, reach) for reach in (5e-8, 2e-7)],
        "hysteresis": [elastic * np.tanh(rate / v0) for v0 in (3e-6, 1e-5)],
        BRUSH: [np.exp(z / decay) for decay in (2e-8, 5e-8, 1e-7, 2e-7)],
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("table")
    parser.add_argument("--surface", type=float, required=True, help="the workflow's surface [m] of the x column")
    parser.add_argument("--rate-width", type=int, default=9, help="samples of the depth's local slope (9)")
    parser.add_argument("--brush", action="store_true",
                        help="add an exponential layer before the surface, F_b·exp(z/λ), λ 20–200 nm")
    args = parser.parse_args()
    effects = EFFECTS[1:] + (BRUSH,) if args.brush else EFFECTS
    t, x, f = read(args.table)
    rate = local_slope(t, x, args.rate_width)
    in_contact = x > args.surface
    best = {}
    for surface_offset in np.arange(-200e-9, 101e-9, 25e-9):
        for a in (1.5, 2.0, 2.5):
            elastic, grid = columns(t, x, rate, args.surface + surface_offset, a)
            for count in range(len(effects) + 1):
                for subset in itertools.combinations(effects, count):
                    for chosen in itertools.product(*(grid[e] for e in subset)):
                        design = np.column_stack([np.ones_like(x), elastic, *chosen])
                        scale = np.abs(design).max(axis=0)
                        scale[scale == 0] = 1.0
                        coef, *_ = np.linalg.lstsq(design / scale, f, rcond=None)
                        residual = f - design / scale @ coef
                        rms = float(np.sqrt(np.mean(residual[in_contact] ** 2)))
                        total = float(np.mean(residual**2))
                        key = count
                        if key not in best or total < best[key][0]:
                            best[key] = (total, rms, subset, surface_offset, a)
    for count in sorted(best):
        _, rms, subset, offset, a = best[count]
        print(f"{count} effects: in contact {rms * 1e12:.1f} pN — {', '.join(subset) or 'the base law alone'} "
              f"(its surface {offset * 1e9:+.0f} nm from the given one, a = {a})")


if __name__ == "__main__":
    main()
