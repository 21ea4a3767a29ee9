"""table2.md and the self-contained report.html of one analysis (images embedded, no script)."""

import base64
import html
import json
import math
import os

from . import JOINT_NAMES
from . import stats
from .paper import CITATION, PAPER_TABLE2


def _shown(path):
    """A path as the user named it relative to the working directory: no machine paths in reports."""
    rel = os.path.relpath(os.path.abspath(path))
    return path if rel.startswith("..") else rel

STAT_LABELS = {"pearson_r": "Pearson r", "spearman_rho": "Spearman ρ", "kendall_tau": "Kendall τ-b",
               "mi_bits": "MI [bits]"}


def fmt(x, digits=3):
    return "–" if x is None or not math.isfinite(x) else "%.*f" % (digits, x)


def fmt_p(p):
    if p is None or not math.isfinite(p):
        return "–"
    return "%.3f" % p if p >= 0.001 else "%.1e" % p


def method_lines(options):
    """The method, one item per line, for table2.md, the report and docs/reproduction.md."""
    return [
        "Pair per movement × joint: joint angular velocity `numpy.gradient(q_j, t_s)` (rad/s) over "
        "every tick of ticks.csv, and the attention score `att_j` (last decoder layer, norm-based).",
        "Ticks: those where the policy was bypassed (fault bits human_timeout or policy_nonfinite: "
        "returning home, or a non-finite action) are dropped after the gradient (column n_dropped); "
        "ticks with only no_human keep the policy running on the held reference and are kept.",
        "Trend removal: %s; the same for both series of every row." % stats.describe_detrend(options["detrend"]),
        "Statistics: Pearson r, Spearman ρ (average ranks), Kendall τ-b, and mutual information in bits "
        "(Kraskov–Stögbauer–Grassberger estimator 1, k = %d, max-norm, series standardised, tie-breaking "
        "jitter 1e-10 from a fixed seed; not clipped at 0)." % stats.KSG_K,
        "95%% intervals: circular block bootstrap (Politis & Romano 1992), %d resamples, percentile "
        "interval; block length per row = the larger of the two series' Politis–White (2004/2009) "
        "automatic block length (column block_len, ticks). For MI the resampled values are first "
        "re-centred on the estimate (their median moved onto it): repeated ticks bias resampled KSG "
        "values upward; copies of the same tick are also never each other's KSG neighbours." % options["bootstrap"],
        "p-values: circular-shift permutation test: every shift s of the attention series with "
        "block_len ≤ s ≤ n − block_len (column n_shifts), two-sided for the correlations, one-sided "
        "(larger) for MI; p = (1 + #{null ≥ observed}) / (1 + n_shifts), so p ≥ 1/(1 + n_shifts).",
        "Seeds: each row's bootstrap and jitter seed is CRC-32 of 'movement/joint/%d'; UMAP random_state 0."
        % options["seed"],
    ]


def table2_markdown(rows, options):
    lines = ["# Table 2: joint angular velocity vs attention score", "",
             "Trend removal: **%s**." % options["detrend"], ""]
    lines += ["- " + m for m in method_lines(options)]
    lines += ["", "Each cell: estimate [95% CI] and the permutation p-value.", ""]
    head = ["movement", "joint"] + [STAT_LABELS[s] for s in stats.STAT_NAMES] + ["n (dropped)", "block"]
    lines.append("| " + " | ".join(head) + " |")
    lines.append("|" + "---|" * len(head))
    for r in rows:
        cells = [r["movement"], r["joint"]]
        for s in stats.STAT_NAMES:
            cells.append("%s [%s, %s] p=%s" % (fmt(r[s]), fmt(r[s + "_ci_lo"]), fmt(r[s + "_ci_hi"]),
                                                fmt_p(r[s + "_p"])))
        cells += ["%d (%d)" % (r["n_ticks"], r["n_dropped"]), str(r["block_len"])]
        lines.append("| " + " | ".join(cells) + " |")
    runs = sorted({(r["run"], r["movement"]) for r in rows})
    lines += ["", "Runs: " + ", ".join("%s (%s)" % (_shown(run), m) for run, m in runs) + ".", ""]
    return "\n".join(lines)


def _img(out_dir, name, alt):
    with open(os.path.join(out_dir, name + ".png"), "rb") as f:
        data = base64.b64encode(f.read()).decode("ascii")
    return ('<figure><img alt="%s" src="data:image/png;base64,%s"><figcaption>%s '
            '(<code>%s.png</code>, <code>%s.svg</code>)</figcaption></figure>'
            % (html.escape(alt), data, html.escape(alt), name, name))


def _table2_html(rows):
    head = "".join("<th>%s</th><th>95%% CI</th><th>p</th>" % html.escape(STAT_LABELS[s]) for s in stats.STAT_NAMES)
    out = ["<table><thead><tr><th>movement</th><th>joint</th>%s<th>n</th><th>dropped</th><th>block</th>"
           "<th>shifts</th></tr></thead><tbody>" % head]
    for r in rows:
        cells = ["<td>%s</td><td>%s</td>" % (html.escape(r["movement"]), html.escape(r["joint"]))]
        for s in stats.STAT_NAMES:
            p = r[s + "_p"]
            cls = ' class="sig"' if math.isfinite(p) and p < 0.05 else ""
            cells.append("<td%s>%s</td><td>[%s, %s]</td><td%s>%s</td>"
                         % (cls, fmt(r[s]), fmt(r[s + "_ci_lo"]), fmt(r[s + "_ci_hi"]), cls, fmt_p(p)))
        cells.append("<td>%d</td><td>%d</td><td>%d</td><td>%d</td>"
                     % (r["n_ticks"], r["n_dropped"], r["block_len"], r["n_shifts"]))
        out.append("<tr>%s</tr>" % "".join(cells))
    out.append("</tbody></table>")
    return "\n".join(out)


def _paper_html(rows):
    ours = {(r["movement"], r["joint"]): r for r in rows}
    out = ["<table><thead><tr><th>movement</th><th>paper joint</th><th>our joint</th>"
           "<th>ρ paper</th><th>ρ ours</th><th>τ paper</th><th>τ ours</th><th>r paper</th><th>r ours</th>"
           "<th>MI paper</th><th>MI ours</th></tr></thead><tbody>"]
    for movement, _, pj, joint, rho, tau, r, mi in PAPER_TABLE2:
        o = ours.get((movement, joint))
        if o is None:
            continue
        out.append("<tr><td>%s</td><td>%s</td><td>%s</td>%s</tr>" % (
            movement, pj, joint, "".join("<td>%.3f</td><td>%s</td>" % (p, fmt(o[s])) for p, s in
                                         ((rho, "spearman_rho"), (tau, "kendall_tau"), (r, "pearson_r"),
                                          (mi, "mi_bits")))))
    out.append("</tbody></table>")
    if len(out) == 2:
        return "<p>No run of the paper's movements (whole_arm, elbow, wrist) in this analysis.</p>"
    return "\n".join(out)


def nao_rt_command(summary, run_path):
    """The nao_rt command line that reproduces a run, from its summary.json (None if unknown)."""
    ref = str(summary.get("reference", ""))
    if not ref.startswith("synthetic:"):
        return None
    args = ["build/bin/nao_rt", "--reference", ref.split()[0], "--seed", str(summary.get("seed", 1))]
    model = summary.get("model", {}).get("path")
    if model and model != "compiled-in":
        args += ["--weights", model]
    if summary.get("realtime"):
        args.append("--realtime")
    return " ".join(args + ["--log", _shown(run_path)])


CSS = """
body { font-family: sans-serif; margin: 1.5em auto; max-width: 1250px; color: #222; line-height: 1.4; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ccc; margin-top: 1.6em; }
table { border-collapse: collapse; font-size: 0.74em; margin: 0.6em 0; }
th, td { border: 1px solid #ccc; padding: 2px 4px; text-align: right; } td { white-space: nowrap; }
th { background: #f0f0f0; } td:first-child, td:nth-child(2), th:first-child, th:nth-child(2) { text-align: left; }
td.sig { background: #e3f2e3; font-weight: bold; }
pre, code { background: #f6f6f6; font-size: 0.85em; } pre { padding: 0.6em; overflow-x: auto; }
figure { margin: 1em 0; } img { max-width: 100%; border: 1px solid #eee; }
figcaption { font-size: 0.85em; color: #555; } .note { color: #555; font-size: 0.9em; }
"""


def report_html(runs, labels, rows, figures, options, command):
    """The whole page as one string. figures: {label or 'umap': [(name, caption), ...]}."""
    out_dir = options["out"]
    parts = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
             "<title>nao-rt attention–motion analysis</title><style>%s</style></head><body>" % CSS,
             "<h1>nao-rt attention–motion analysis</h1>",
             '<p class="note">Paper Table 2 and Figs. 8–16 from nao_rt runs (DESIGN §10), with what the '
             "paper lacks: block-bootstrap confidence intervals and shift-test p-values.</p>",
             "<h2>Command</h2><pre>%s</pre>" % html.escape(command),
             "<p>Runs: %s. Output: <code>%s</code>.</p>" % (
                 ", ".join("<code>%s</code> (%s)" % (html.escape(_shown(r.path)), html.escape(lab)) for r, lab in zip(runs, labels)),
                 html.escape(_shown(out_dir))),
             "<h2>Table 2: angular velocity vs attention score</h2>",
             "<p>Cells with p &lt; 0.05 (shift test) are shaded. Trend removal: <b>%s</b>.</p>"
             % html.escape(options["detrend"]),
             _table2_html(rows),
             "<h3>Method</h3><ul>%s</ul>" % "".join("<li>%s</li>" % html.escape(m).replace("`", "")
                                                      for m in method_lines(options)),
             "<h3>Beside the paper's Table 2</h3>",
             "<p class=\"note\">The paper's “Elbow roll” is NAOqi's RElbowYaw (its Table 1 ranges). "
             "Source: %s.</p>" % html.escape(CITATION),
             _paper_html(rows)]
    for run, lab in zip(runs, labels):
        parts.append("<h2>Run %s</h2>" % html.escape(lab))
        for name, caption in figures.get(lab, []):
            parts.append(_img(out_dir, name, caption))
    if figures.get("umap"):
        parts.append("<h2>UMAP of the cross-attention outputs</h2>")
        for name, caption in figures["umap"]:
            parts.append(_img(out_dir, name, caption))
    parts.append("<h2>Runs: summary.json and commands</h2>")
    for run, lab in zip(runs, labels):
        cmd = nao_rt_command(run.summary, run.path)
        parts.append("<h3>%s</h3>" % html.escape(lab))
        parts.append("<p><code>%s</code>: %d ticks, %d of them dropped from Table 2 (policy bypassed).</p>"
                     % (html.escape(_shown(run.path)), run.n_ticks, run.n_ticks - int(run.policy_mask().sum())))
        if cmd:
            parts.append("<p>nao_rt command (rebuilt from summary.json):</p><pre>%s</pre>" % html.escape(cmd))
        parts.append("<pre>%s</pre>" % html.escape(json.dumps(run.summary, indent=2)))
    parts.append("<p class=\"note\">Joint order: %s. Files: table2.csv, table2.md, fig_*.png/svg in "
                 "the output directory.</p>" % ", ".join(JOINT_NAMES))
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"
