#!/usr/bin/python3
"""Renders the examples' CSV (written by the nupmpc-example-* programs) as PNG figures
like [KL] Figs. 2, 18, 19, 20, 21 and 23. Usage: plot_examples.py DIR (reads and writes DIR).
Needs Debian's python3-matplotlib."""
import csv
import math
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.patches as patches  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402


def read(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return {k: [float(r[k]) for r in rows if r[k] != ""] for k in rows[0]}


def against_exhaustive(ax, t, output, label, title):
    """The target, one NUP output and the exhaustive horizon-8 controller's output."""
    ax.plot(t["step"], t["target"], "k--", label="target")
    ax.plot(t["step"], t[output], label=label)
    ax.plot(t["step"], t["exhaustive_output"], ":", label="exhaustive, horizon 8")
    ax.set_title(title)
    ax.legend(loc="upper right", fontsize=7)


def dac(d):
    fig, axes = plt.subplots(4, 1, figsize=(8, 10.5))
    for ax, hz in zip(axes[:2], (2, 40)):
        t = read(f"{d}/dac_long_{hz}hz.csv")
        ax.plot(t["step"], t["target"], "k--", label="target")
        ax.plot(t["step"], t["output"], label="output y")
        ax.step(t["step"][:-1], t["input"], where="post", alpha=0.3, label="binary input u")
        ax.set_title(f"DAC, one plan K = 450, target {hz} Hz")
        ax.legend(loc="upper right", fontsize=7)
    against_exhaustive(axes[2], read(f"{d}/dac_online.csv"), "nup_output", "IAKE-EM, horizon 8",
                       "DAC receding horizon (Fig. 19)")
    against_exhaustive(axes[3], read(f"{d}/dac_fig18.csv"), "long_output", "IAKE-EM, one plan K = 300",
                       "DAC long horizon vs exhaustive horizon 8, target 5 Hz (Fig. 18)")
    fig.tight_layout()
    fig.savefig(f"{d}/dac.png", dpi=120)


def corridor(d):
    t = read(f"{d}/corridor.csv")
    versions = ["l2_input", "rate_limit", "sparse_input", "three_levels", "sparse_changes"]
    fig, axes = plt.subplots(6, 1, figsize=(8, 12), sharex=True)
    w = t["half_width"][0]
    lo = [y - w for y in t["target"]]
    hi = [y + w for y in t["target"]]
    axes[0].plot(t["step"], lo, "k--", t["step"], hi, "k--")
    for v in versions:
        axes[0].plot(t["step"], t["y_" + v], label=v)
    axes[0].legend(fontsize=7)
    axes[0].set_title("corridor control (Fig. 20): outputs")
    for ax, v in zip(axes[1:], versions):
        ax.step(t["step"][: len(t["u_" + v])], t["u_" + v], where="post")
        ax.set_ylabel(v, fontsize=8)
    fig.tight_layout()
    fig.savefig(f"{d}/corridor.png", dpi=120)


def flappy(d):
    t = read(f"{d}/flappy_bird.csv")
    walls = read(f"{d}/flappy_walls.csv")
    fig, ax = plt.subplots(figsize=(10, 4))
    for first, width, low, sep in zip(walls["first_step"], walls["width"], walls["upper_low"], walls["separation"]):
        # Bars: below the lower slit, between the slits, above the upper slit.
        for y0, y1 in ((0, low - sep), (low - sep + 1, low), (low + 1, 10)):
            ax.add_patch(patches.Rectangle((first, y0), width, y1 - y0, color="k"))
    ax.plot(t["step"], t["height"], label="height y")
    flaps = [s for s, u in zip(t["step"], t["flap"]) if u > 0.5]
    ax.plot(flaps, [0.2] * len(flaps), "r|", label="flap u = 1")
    ax.set_ylim(0, 10)
    ax.legend(loc="upper right", fontsize=7)
    ax.set_title("flappy bird (Fig. 21)")
    fig.tight_layout()
    fig.savefig(f"{d}/flappy_bird.png", dpi=120)


def obstacles(d):
    regions = read(f"{d}/obstacles_regions.csv")
    fig, axes = plt.subplots(1, 2, figsize=(10, 5))
    for scene, (ax, name) in enumerate(zip(axes, ("single", "mixed"))):
        for i, s in enumerate(regions["scene"]):
            if int(s) != scene:
                continue
            c = (regions["c1"][i], regions["c2"][i])
            a, b, rot = regions["a"][i], regions["b"][i], regions["rotation"][i]
            if regions["shape"][i] == 0:
                shape = patches.Ellipse(c, 2 * a, 2 * b, angle=math.degrees(rot), color="grey")
            else:
                corner = (c[0] - a * math.cos(rot) + b * math.sin(rot), c[1] - a * math.sin(rot) - b * math.cos(rot))
                shape = patches.Rectangle(corner, 2 * a, 2 * b, angle=math.degrees(rot), color="grey")
            ax.add_patch(shape)
        t = read(f"{d}/obstacles_{name}.csv")
        ax.plot(t["p1"], t["p2"], "o-", ms=3)
        ax.set_aspect("equal")
        ax.set_xlim(-0.2, 3.4)
        ax.set_ylim(-0.2, 3.4)
        ax.set_title(f"obstacle avoidance: {name} (Fig. 23)")
    fig.tight_layout()
    fig.savefig(f"{d}/obstacles.png", dpi=120)


def race_track(d):
    """[KL] Fig. 25: the minimal-time race line coloured by speed, and a_tot² along s."""
    t = read(f"{d}/race_track.csv")
    fig, (plane, profile) = plt.subplots(1, 2, figsize=(12, 5), gridspec_kw={"width_ratios": [3, 2]})
    for side in ("left", "right"):
        plane.plot(t[f"{side}_x"], t[f"{side}_y"], color="0.5", linewidth=0.6)
    line = plane.scatter(t["x"], t["y"], c=t["speed"], s=2, cmap="viridis", label="race line")
    fig.colorbar(line, ax=plane, label="speed v")
    plane.set_aspect("equal")
    plane.set_title(f"minimal-time lap: {t['t'][-1]:.3f} s")
    plane.set_xlabel("track edges: 0.006 either side of the centre line (z in the right panel)", fontsize=8)
    profile.plot(t["s"], t["speed"], label="v")
    profile.plot(t["s"], [a / 150 for a in t["a_total_sq"]], label="a_tot² / 150")
    profile.plot(t["s"], [z / 0.006 for z in t["z"]], linewidth=0.8, label="z / 0.006")
    profile.set_xlabel("s (arc length of the centre line)")
    profile.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(f"{d}/race_track.png", dpi=120)


def gp_closed_loop(d):
    """[Nghiem] §V: closed loops driven by linGP-SCP and by Ipopt (nupmpc-gp-bench --csv)."""
    import glob
    import os
    for path in sorted(glob.glob(f"{d}/gp_closed_loop_N*.csv")):
        t = read(path)
        name = os.path.splitext(os.path.basename(path))[0]
        steps = list(range(len(t["y_scp"])))
        fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
        top.step(steps, t["reference"], "k--", where="post", label="reference")
        top.plot(steps, t["y_scp"], label="y, linGP-SCP (NUP)")
        if t.get("y_ipopt"):
            top.plot(steps, t["y_ipopt"], ":", label="y, Ipopt")
        top.set_title(f"GP-MPC closed loop, N = {name.split('_N')[-1]} training points")
        top.legend(fontsize=7)
        bottom.step(steps, t["u_scp"], where="post", label="u, linGP-SCP")
        if t.get("u_ipopt"):
            bottom.step(steps, t["u_ipopt"], ":", where="post", label="u, Ipopt")
        bottom.set_xlabel("step")
        bottom.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(f"{d}/{name}.png", dpi=120)


if __name__ == "__main__":
    directory = sys.argv[1] if len(sys.argv) > 1 else "figures"
    for plot in (dac, corridor, flappy, obstacles, race_track, gp_closed_loop):
        plot(directory)
        print(f"{plot.__name__}: written to {directory}")
