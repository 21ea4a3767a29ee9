"""Figures of paper Figs. 8-16 for each run, and the UMAP of the cross-attention outputs.

Each figure is written as NAME.png and NAME.svg; the functions return NAME. Matplotlib runs
headless (Agg) with a fixed SVG hash salt and no dates in the metadata, so the same data give
the same files.
"""

import os
import warnings

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend choice)
import numpy as np  # noqa: E402
from matplotlib.gridspec import GridSpec  # noqa: E402

from . import JOINT_NAMES  # noqa: E402
from . import kinematics  # noqa: E402

plt.rcParams.update({
    "svg.hashsalt": "nao-rt-analysis",  # fixed element ids: reproducible SVGs
    "svg.fonttype": "none",              # text stays text: small, searchable SVGs
    "font.size": 9,
    "axes.titlesize": 10,
    "legend.fontsize": 8,
    "figure.dpi": 100,
})
PNG_DPI = 110
JOINT_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple")
# Paper Figs. 8-10: green human-derived, blue feature-extracted, red robot.
PATH_STYLES = (("human-derived target: FK(q_ref)", "tab:green"),
               ("feature-extracted demonstration: ee_ref", "tab:blue"),
               ("robot: ee", "tab:red"))
INSTANT_FRACTIONS = (0.125, 0.375, 0.625, 0.875)
INSTANT_LABELS = ("a", "b", "c", "d")
UMAP_SEED = 0


def save(fig, out_dir, name):
    """NAME.png and NAME.svg in out_dir; closes the figure."""
    fig.savefig(os.path.join(out_dir, name + ".png"), dpi=PNG_DPI, metadata={"Software": None})
    fig.savefig(os.path.join(out_dir, name + ".svg"), metadata={"Date": None, "Creator": None})
    plt.close(fig)
    return name


def instants(run):
    """Indices of the four marked ticks a-d: the kept ticks nearest 1/8, 3/8, 5/8, 7/8 of the run."""
    t = run.columns["t_s"]
    kept = np.flatnonzero(run.policy_mask())
    targets = t[0] + np.array(INSTANT_FRACTIONS) * (t[-1] - t[0])
    return [int(kept[np.argmin(np.abs(t[kept] - x))]) for x in targets]


def _shade_dropped(ax, run):
    """Grey bands over the ticks whose attention is not the policy's (dropped from Table 2)."""
    t = run.columns["t_s"]
    dt = float(np.median(np.diff(t)))
    for i in np.flatnonzero(~run.policy_mask()):
        ax.axvspan(t[i] - dt / 2, t[i] + dt / 2, color="0.85", lw=0, zorder=0)


# An autonomous run has no reference to draw; `nao_toolchain evaluate` leaves beside it the
# demonstration its code names (named_demo.csv) and the held-out one it starts from
# (../../demos/<run>.csv): drawn in their place, as the paper draws the demonstration.
AUTONOMOUS_PATH_STYLES = (("held-out demonstration it starts from", "tab:green"),
                          ("demonstration its code names (it plays this one)", "tab:blue"),
                          ("robot: ee", "tab:red"))


def _trajectory_csv(path):
    """The (n, 5) joint trajectory of an evaluate CSV (t_s,q_0..q_4), or None without the file."""
    if not os.path.isfile(path):
        return None
    q = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    if q.shape[1] != 6:
        raise ValueError("%s: expected the columns t_s,q_0..q_4" % path)
    return q[:, 1:]


def autonomous_demonstrations(run):
    """(held-out, named) joint trajectories beside an autonomous run (None where absent), or
    None for a run with a reference."""
    if np.isfinite(run.columns["ee_ref_x"]).any():
        return None
    held = _trajectory_csv(os.path.join(run.path, "..", "..", "demos",
                                        os.path.basename(os.path.normpath(run.path)) + ".csv"))
    return held, _trajectory_csv(os.path.join(run.path, "named_demo.csv"))


def _hand_paths(run, arm):
    """[(points (n, 3), legend, colour)] of the hand-path figure; the robot's last."""
    p_robot = np.column_stack([run.columns[c] for c in ("ee_x", "ee_y", "ee_z")])
    demos = autonomous_demonstrations(run)
    if demos is None:
        p_human = kinematics.hand_position(arm, run.joint_matrix("q_ref"))
        p_feat = np.column_stack([run.columns[c] for c in ("ee_ref_x", "ee_ref_y", "ee_ref_z")])
        return [(p, name, color) for p, (name, color) in zip((p_human, p_feat, p_robot), PATH_STYLES)]
    paths = [(kinematics.hand_position(arm, q), name, color)
             for q, (name, color) in zip(demos, AUTONOMOUS_PATH_STYLES) if q is not None]
    return paths + [(p_robot,) + AUTONOMOUS_PATH_STYLES[2]]


def hand_path_caption(run, label):
    """The report's caption of figure_ee for this run."""
    demos = autonomous_demonstrations(run)
    if demos is None:
        return ("%s: hand trajectory (paper Figs. 8–10): green human-derived target FK(q_ref), blue "
                "feature-extracted demonstration ee_ref, red robot ee; a–d mark the instants of the "
                "attention figure" % label)
    parts = [text for q, text in zip(demos, ("green the held-out demonstration the run starts from",
                                              "blue the training demonstration its code names, the one it plays"))
             if q is not None]
    return ("%s: hand trajectory of the autonomous run (paper Figs. 8–10): %sred the robot's hand; a–d mark "
            "the instants of the attention figure" % (label, "".join(p + ", " for p in parts)))


def figure_ee(run, label, arm, out_dir):
    """Paper Figs. 8-10: hand trajectories in 3D and in the three projections, torso frame."""
    paths = _hand_paths(run, arm)
    marks = instants(run)
    fig = plt.figure(figsize=(11, 8.2))
    gs = GridSpec(2, 2, figure=fig, hspace=0.3, wspace=0.25)
    ax3 = fig.add_subplot(gs[0, 0], projection="3d")
    for p, name, color in paths:
        ax3.plot(p[:, 0], p[:, 1], p[:, 2], color=color, lw=1.2, label=name)
    robot = paths[-1][0]
    for m, lab in zip(marks, INSTANT_LABELS):
        ax3.scatter(*robot[m], color="k", s=12)
        ax3.text(*robot[m], " " + lab, fontsize=9)
    ax3.set_xlabel("x [m]")
    ax3.set_ylabel("y [m]")
    ax3.set_zlabel("z [m]")
    ax3.set_title("3D (torso frame)")
    views = ((gs[0, 1], 0, 1, "top view: x-y"), (gs[1, 0], 0, 2, "side view: x-z"), (gs[1, 1], 1, 2, "front view: y-z"))
    for cell, i, k, title in views:
        ax = fig.add_subplot(cell)
        for p, name, color in paths:
            ax.plot(p[:, i], p[:, k], color=color, lw=1.2, label=name)
        for m, lab in zip(marks, INSTANT_LABELS):
            ax.plot(robot[m, i], robot[m, k], "k.", ms=5)
            ax.annotate(lab, (robot[m, i], robot[m, k]), textcoords="offset points", xytext=(3, 3), fontsize=9)
        ax.set_xlabel("xyz"[i] + " [m]")
        ax.set_ylabel("xyz"[k] + " [m]")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(title)
        ax.grid(alpha=0.3)
    handles, names = ax.get_legend_handles_labels()
    fig.legend(handles, names, loc="upper center", bbox_to_anchor=(0.5, 0.955), ncol=3, frameon=False)
    fig.suptitle("%s: hand (end-effector) trajectory in the torso frame; a-d as in the attention figure"
                 % label, y=0.99)
    return save(fig, out_dir, "fig_ee_%s" % label)


def _stick(ax, points, title):
    """The torso and the right arm as lines, seen from the front-right (3D axes)."""
    torso = np.array([[0, 0, 0], [0, 0, 0.1], [0, -0.098, 0.1], [0, 0, 0.1], [0, 0.098, 0.1]])
    ax.plot(torso[:, 0], torso[:, 1], torso[:, 2], color="0.5", lw=2)
    arm = points[[0, 2, 4, 5]]  # shoulder, elbow, wrist, hand (coincident joint origins merged)
    ax.plot(arm[:, 0], arm[:, 1], arm[:, 2], color="k", lw=2.5, marker="o", ms=4)
    # The hand reaches 0.22 m from the shoulder (0, -0.098, 0.1) in every direction.
    ax.set_xlim(-0.15, 0.25)
    ax.set_ylim(-0.35, 0.15)
    ax.set_zlim(-0.15, 0.35)
    ax.set_box_aspect((0.4, 0.5, 0.5))
    ax.view_init(elev=20, azim=-55)
    ax.set_xticks([-0.1, 0.0, 0.1, 0.2])
    ax.set_yticks([-0.3, -0.2, -0.1, 0.0])
    ax.set_zticks([-0.1, 0.0, 0.1, 0.2])
    ax.set_xlabel("x [m]", labelpad=-6)
    ax.set_ylabel("y [m]", labelpad=-6)
    ax.set_zlabel("z [m]", labelpad=-6)
    ax.tick_params(labelsize=6, pad=-2)
    ax.set_title(title, fontsize=9, y=0.98)


def figure_attention(run, label, arm, out_dir):
    """Paper Figs. 11-13: attention per body part over time, and the pose and scores at a-d."""
    t = run.columns["t_s"]
    att = run.joint_matrix("att")
    marks = instants(run)
    points = kinematics.arm_points(arm, run.joint_matrix("q")[marks])
    fig = plt.figure(figsize=(12, 10))
    gs = GridSpec(3, 4, figure=fig, height_ratios=(1.0, 1.45, 0.8), hspace=0.45, wspace=0.15,
                  top=0.88, bottom=0.1, left=0.07, right=0.98)
    ax = fig.add_subplot(gs[0, :])
    _shade_dropped(ax, run)
    for j, name in enumerate(JOINT_NAMES):
        ax.plot(t, att[:, j], color=JOINT_COLORS[j], lw=1.2, label=name)
    for m, lab in zip(marks, INSTANT_LABELS):
        ax.axvline(t[m], color="k", lw=0.8, ls="--")
        ax.text(t[m], 1.01, lab, transform=ax.get_xaxis_transform(), ha="center", va="bottom")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("attention score [-]")
    ax.set_xlim(t[0], t[-1])
    ax.legend(ncol=5, loc="lower center", bbox_to_anchor=(0.5, 1.06), frameon=False)
    ax.grid(alpha=0.3)
    top = float(np.nanmax(att[marks])) * 1.1
    for c, (m, lab) in enumerate(zip(marks, INSTANT_LABELS)):
        a3 = fig.add_subplot(gs[1, c], projection="3d")
        _stick(a3, points[c], "(%s) t = %.1f s" % (lab, t[m]))
        ab = fig.add_subplot(gs[2, c])
        ab.bar(range(len(JOINT_NAMES)), att[m], color=JOINT_COLORS)
        ab.set_xticks(range(len(JOINT_NAMES)))
        ab.set_xticklabels(JOINT_NAMES, rotation=40, ha="right", fontsize=7)
        ab.set_ylim(0, top)
        if c == 0:
            ab.set_ylabel("attention score [-]")
    fig.suptitle("%s: attention per body part (last decoder layer, norm-based) and the robot pose at a-d"
                 % label, y=0.985)
    return save(fig, out_dir, "fig_attention_%s" % label)


def figure_motion(run, label, out_dir):
    """Paper Figs. 14-16: joint angle, velocity, acceleration and attention on one time axis."""
    t = run.columns["t_s"]
    q = run.joint_matrix("q")
    v = np.gradient(q, t, axis=0)
    acc = np.gradient(v, t, axis=0)
    att = run.joint_matrix("att")
    panels = (("(a) joint angle [rad]", q), ("(b) angular velocity [rad/s]", v),
              ("(c) angular acceleration [rad/s$^2$]", acc), ("(d) attention score [-]", att))
    fig, axes = plt.subplots(4, 1, sharex=True, figsize=(10, 10))
    for ax, (ylabel, y) in zip(axes, panels):
        _shade_dropped(ax, run)
        for j, name in enumerate(JOINT_NAMES):
            ax.plot(t, y[:, j], color=JOINT_COLORS[j], lw=1.1, label=name)
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    axes[0].legend(ncol=5, loc="lower center", bbox_to_anchor=(0.5, 1.0), frameon=False)
    axes[-1].set_xlabel("time [s]")
    axes[-1].set_xlim(t[0], t[-1])
    fig.suptitle("%s: joint motion and attention (velocity = numpy.gradient(q, t_s))" % label)
    fig.tight_layout()
    return save(fig, out_dir, "fig_motion_%s" % label)


def key_pose_phase(run):
    """Movement phase of every tick: the key pose (k-means++ centroid) the
    reference snapped to, numbered 1, 2, ... in the order the run first reaches them."""
    r = run.joint_matrix("r")
    _, first, inverse = np.unique(r, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(np.argsort(first))  # unique row -> rank of its first appearance
    return order[inverse.ravel()] + 1


def umap_embedding(runs, labels):
    """2-D UMAP of the cross-attention outputs, one point per kept tick of every run.

    A point is the last decoder layer's cross-attention output of all five action tokens of a
    tick (cross_out, 5 x d_model, concatenated). Returns (embedding (N, 2), run index (N,),
    record index (N,))."""
    import umap  # slow to import (numba): only when the figure is made

    X, which, rec = [], [], []
    for i, run in enumerate(runs):
        att = run.attention
        keep = run.policy_mask()[att.tick]
        X.append(att.cross_out[keep].reshape(int(keep.sum()), -1).astype(np.float64))
        which.append(np.full(int(keep.sum()), i))
        rec.append(np.flatnonzero(keep))
    X = np.concatenate(X)
    with warnings.catch_warnings():
        # umap warns that a fixed random_state turns off its parallelism: that is the point.
        warnings.simplefilter("ignore")
        reducer = umap.UMAP(n_components=2, n_neighbors=min(15, len(X) - 1), min_dist=0.1,
                            metric="euclidean", random_state=UMAP_SEED)
        emb = reducer.fit_transform(X)
    return emb, np.concatenate(which), np.concatenate(rec)


def figure_umap(runs, labels, out_dir):
    """UMAP of the cross-attention outputs coloured by run, by time and by movement phase."""
    emb, which, rec = umap_embedding(runs, labels)
    markers = ("o", "s", "^", "D", "v", "P", "X", "*")
    fig, axes = plt.subplots(1, 3, figsize=(15, 5))
    t_all = np.concatenate([run.columns["t_s"][run.attention.tick[rec[which == i]]] for i, run in enumerate(runs)])
    ph_all = np.concatenate([key_pose_phase(run)[run.attention.tick[rec[which == i]]] for i, run in enumerate(runs)])
    order = np.argsort(which, kind="stable")
    emb_o = emb[order]
    n_phase = int(ph_all.max())
    cmap_phase = plt.get_cmap("tab10" if n_phase <= 10 else "tab20", max(n_phase, 1))
    for i, lab in enumerate(labels):
        sel = which[order] == i
        e = emb_o[sel]
        mk = markers[i % len(markers)]
        axes[0].scatter(e[:, 0], e[:, 1], s=12, marker=mk, label=lab)
        sc = axes[1].scatter(e[:, 0], e[:, 1], s=12, marker=mk, c=t_all[sel], cmap="viridis",
                             vmin=0, vmax=float(t_all.max()))
        sp = axes[2].scatter(e[:, 0], e[:, 1], s=12, marker=mk, c=ph_all[sel], cmap=cmap_phase,
                             vmin=0.5, vmax=n_phase + 0.5)
        # The path through time, faintly, in the time panel.
        axes[1].plot(e[:, 0], e[:, 1], color="0.7", lw=0.4, zorder=0)
    axes[0].legend(title="run (marker)", loc="best")
    fig.colorbar(sc, ax=axes[1], label="time [s]")
    cb = fig.colorbar(sp, ax=axes[2], label="movement phase: key pose, in order of first use")
    cb.set_ticks(range(1, n_phase + 1))
    for ax, title in zip(axes, ("by run", "by time", "by movement phase (k-means++ key pose)")):
        ax.set_xlabel("UMAP 1 [-]")
        ax.set_ylabel("UMAP 2 [-]")
        ax.set_title(title)
        ax.grid(alpha=0.3)
    fig.suptitle("UMAP of the last decoder layer's cross-attention output (5 action tokens x d_model per tick, "
                 "random_state %d)" % UMAP_SEED)
    fig.tight_layout()
    return save(fig, out_dir, "fig_umap")


def figure_age_profile(runs, labels, out_dir):
    """The temporal attention profile (attention.bin format 2): the last decoder layer's mean
    cross-attention mass per age (0 = the tick itself) over the ticks of full windows, per
    movement, with the spread over runs; None when no run carries it (format 1)."""
    by_movement = {}
    for run in runs:
        att = run.attention
        if att is None or att.age_profile is None or att.window < 1:
            continue
        full = att.tick >= att.window - 1  # ticks whose window holds W ticks of history
        if not full.any():
            continue
        by_movement.setdefault(run.movement, []).append(att.age_profile[full].mean(axis=0))
    if not by_movement:
        return None
    fig, ax = plt.subplots(figsize=(7, 4))
    for movement in sorted(by_movement):
        per_run = np.array(by_movement[movement])
        ages = np.arange(per_run.shape[1]) * 0.1
        mean = per_run.mean(axis=0)
        ax.plot(ages, mean, marker="o", ms=3, label="%s (%d runs)" % (movement, per_run.shape[0]))
        if per_run.shape[0] > 1:
            ax.fill_between(ages, per_run.min(axis=0), per_run.max(axis=0), alpha=0.2)
    ax.set_xlabel("age of the attended tick [s] (0 = the current tick)")
    ax.set_ylabel("cross-attention mass [-] (sums to 1)")
    ax.set_title("Temporal attention profile, last decoder layer (band: range over runs)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    return save(fig, out_dir, "fig_age_profile")
