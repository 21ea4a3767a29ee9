"""docs/reproduction.md from the Table 2 files of several training seeds
(`toolchain/nao analyze --reproduction-from docs/reproduction/seed_*.json`).

Everything in the page comes from the JSON files (table_json.py), so the page is remade by one
command from committed numbers; hand edits would be lost.
"""

import math
import os

from . import JOINT_NAMES, AnalysisError
from . import verdict
from .paper import CITATION, PAPER_TABLE2
from .report import fmt, fmt_p
from .table_json import read_table_json, row_from_json

REPO = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", ".."))
DOC = os.path.join(REPO, "docs", "reproduction.md")
MOVEMENTS = ("whole_arm", "elbow", "wrist")


def load_seeds(paths):
    """{training seed: document} of the JSON files. Raises AnalysisError when a file has no
    training seed or two files name the same seed."""
    docs = {}
    for p in paths:
        doc = read_table_json(p)
        seed = doc.get("training_seed")
        if not isinstance(seed, int):
            raise AnalysisError("%s: no training_seed (analyse with --training-seed N)" % p)
        if seed in docs:
            raise AnalysisError("%s: training seed %d appears in two files" % (p, seed))
        doc["_path"] = p
        docs[seed] = doc
    if not docs:
        raise AnalysisError("--reproduction-from needs at least one Table 2 file")
    return docs


def seed_rows(doc, score=verdict.SCORE):
    """{(movement, joint): row} of one document's score."""
    return {(o["movement"], o["joint"]): row_from_json(o) for o in doc["table2"].get(score, [])}


def _ci(r, s, digits=2):
    return "%s [%s, %s]" % (fmt(r[s], digits), fmt(r[s + "_ci_lo"], digits), fmt(r[s + "_ci_hi"], digits))


def _cell(r, s):
    return "%s, p %s" % (_ci(r, s), fmt_p(r[s + "_p"]))


def _mi_cell(r):
    return "%s (null %s, q95 %s; excess %s%s)" % (fmt(r["mi_bits"], 2), fmt(r["mi_null_median"], 2),
                                                  fmt(r["mi_null_q95"], 2), fmt(r["mi_excess"], 2),
                                                  ", above q95" if r["mi_above_null"] else "")


def _ordered(movements):
    return [m for m in MOVEMENTS if m in movements] + sorted(m for m in movements if m not in MOVEMENTS)


def verdict_section(found, seeds):
    L = ["## The paper's findings, by the rule", "", "Criterion: " + verdict.CRITERION, ""]
    if len(seeds) < verdict.N_SEEDS:
        L += ["Seeds analysed: %s, fewer than the rule's %d: no finding can be *reproduced* here."
              % (", ".join(str(s) for s in seeds), verdict.N_SEEDS), ""]
    for f in found:
        L += ["### (%s) %s: **%s**" % (f["id"], f["title"], f["verdict"]), "",
              "Paper (§4.2): %s" % f["paper"], "",
              "%d of %d (row, seed) pairs hold." % (f["n_held"], f["n_needed"]), "",
              "| movement | joint | paper ρ | seed | our ρ [95 % interval] | holds |", "|---|---|---|---|---|---|"]
        for movement, joint, seed, holds, why, row in f["checks"]:
            rho = next(p[4] for p in PAPER_TABLE2 if (p[0], p[3]) == (movement, joint))
            L.append("| %s | %s | %.2f | %d | %s | %s |" % (movement, joint, rho, seed,
                                                           _ci(row, "spearman_rho") if row else "–",
                                                           "yes" if holds else "no: " + why))
        L.append("")
    return L


def paper_rows_section(docs):
    seeds = sorted(docs)
    L = ["## The paper's Table 2 rows beside ours", "",
         "The paper's \"Elbow roll\" is NAOqi's RElbowYaw (its Table 1 ranges). Ours per seed: estimate [95 % "
         "interval over distinct rollouts]; MI with the median and 95 % quantile of its circular-shift null and "
         "the excess over the median. The paper gives no intervals and no null.", ""]
    nulls = [r["mi_null_median"] for s in seeds for r in seed_rows(docs[s]).values()
             if math.isfinite(r["mi_null_median"])]
    if nulls:
        paper_mi = [p[7] for p in PAPER_TABLE2]
        L += ["The paper reads its MI values of %.2f–%.2f bits as information beyond the correlations. On our "
              "rollouts the circular-shift null alone, attention and velocity misaligned on purpose, gives a "
              "median MI of %.2f–%.2f bits (every row, every seed): the KSG estimator reads the smoothness of "
              "10 Hz series as information, so an MI near 1 bit is no evidence by itself; only the excess over "
              "the null is." % (min(paper_mi), max(paper_mi), min(nulls), max(nulls)), ""]
    for m, _, pj, oj, rho, tau, r, mi in PAPER_TABLE2:
        L += ["**%s, %s (%s)**: paper ρ %.2f, τ %.2f, r %.2f, MI %.2f bits." % (m, pj, oj, rho, tau, r, mi), "",
              "| seed | Spearman ρ | Kendall τ | Pearson r | MI [bits] |", "|---|---|---|---|---|"]
        for s in seeds:
            o = seed_rows(docs[s]).get((m, oj))
            if o is None:
                L.append("| %d | – | – | – | – |" % s)
                continue
            L.append("| %d | %s | %s | %s | %s |" % (s, _ci(o, "spearman_rho"), _ci(o, "kendall_tau"),
                                                     _ci(o, "pearson_r"), _mi_cell(o)))
        L.append("")
    return L


def units_section(docs):
    L = ["## Runs and distinct rollouts", "",
         "One autonomous rollout per held-out demonstration (its s_0, its length). Runs whose hand paths lie "
         "within %s mm of each other (DTW mean distance over their common ticks) repeat one rollout and form one "
         "unit; each unit enters the statistics once (its longest run), and the bootstrap and the permutations "
         "draw units." % fmt(1e3 * _unit_threshold(docs), 1), "",
         "| seed | movement | runs | distinct rollouts | ticks used | largest DTW inside a unit [mm] | smallest DTW "
         "between units [mm] |", "|---|---|---|---|---|---|---|"]
    for s in sorted(docs):
        mv = docs[s]["movements"]
        for m in _ordered(mv):
            e = mv[m]
            L.append("| %d | %s | %d | %d | %d | %s | %s |" % (
                s, m, e["n_runs"], e["n_units"], e["n_ticks"], _mm(e.get("max_dtw_within_unit_m")),
                _mm(e.get("min_dtw_between_units_m"))))
    return L + [""]


def _mm(x):
    return "–" if x is None else "%.3f" % (1e3 * x)


def _unit_threshold(docs):
    return next(iter(docs.values()))["method"].get("unit_dtw_m") or math.nan


def table_section(docs):
    L = ["## Table 2, every joint, per seed", "",
         "Norm-based score `att_j` (the raw mass `attm_j` is in the JSON files). Each correlation: estimate [95 % "
         "interval], permutation p. MI: estimate, its circular-shift null (median, 95 % quantile) and the excess "
         "over the median; an MI is evidence of dependence only above the null's 95 % quantile.", ""]
    for s in sorted(docs):
        L += ["### Seed %d" % s, "",
              "| movement | joint | Pearson r | Spearman ρ | Kendall τ-b | MI [bits] | runs / units | ticks |",
              "|---|---|---|---|---|---|---|---|"]
        rows = seed_rows(docs[s])
        for m in _ordered({k[0] for k in rows}):
            for j in JOINT_NAMES:
                r = rows.get((m, j))
                if r is None:
                    continue
                L.append("| %s | %s | %s | %s | %s | %s | %d / %d | %d |" % (
                    m, j, _cell(r, "pearson_r"), _cell(r, "spearman_rho"), _cell(r, "kendall_tau"), _mi_cell(r),
                    r["n_runs"], r["n_units"], r["n_ticks"]))
        L.append("")
    return L


def mass_section(docs):
    L = ["## How far the attention is from uniform", "",
         "The last decoder layer's cross-attention mass per body part (attention.bin), over every tick of the "
         "distinct rollouts: its range, against the uniform 0.20, and per body part its variation over time "
         "(standard deviation / mean).", "",
         "| seed | movement | ticks | mass min–max | mean per body part | variation over time |", "|---|---|---|---|---|---|"]
    any_row = False
    for s in sorted(docs):
        mass = docs[s].get("attention_mass") or {}
        for m in _ordered(mass):
            e = mass[m]
            if not e:
                continue
            any_row = True
            L.append("| %d | %s | %d | %.2f–%.2f | %s | %s |" % (
                s, m, e["n_ticks"], e["min"], e["max"], " / ".join("%.2f" % x for x in e["mean"]),
                " / ".join("%.0f %%" % (100 * x) for x in e["cv_over_time"])))
    if not any_row:
        L = L[:2] + ["No run has attention.bin masses (payload format 2)."]
    return L + [""]


def ablation_section(docs):
    L = ["## Attention against ablation", "",
         "Per tick, Spearman ρ between the five body parts' attention masses and how far masking each body part "
         "(its cross-attention logits set to −∞ in every decoder layer over the whole window) moves the executed "
         "action (`ablation.csv`); the median over ticks, and how often the most-attended body part is the one "
         "whose masking moves the action most, against the %.2f of a random pick. 95 %% intervals over distinct "
         "rollouts. Attention predicts the ablation only when both intervals lie above chance." % 0.2, ""]
    rows = []
    for s in sorted(docs):
        ab = docs[s].get("ablation") or {}
        for m in _ordered(ab):
            e = ab[m]
            if e:
                rows.append("| %d | %s | %d of %d | %d | %s [%s, %s] | %s [%s, %s] | %.2f | %s |" % (
                    s, m, e["n_units"], e["n_units_total"], e["n_ticks"], fmt(e["rho_median"], 2),
                    fmt(_unnone(e["rho_ci"][0]), 2), fmt(_unnone(e["rho_ci"][1]), 2), fmt(e["top_match_rate"], 2),
                    fmt(_unnone(e["top_match_ci"][0]), 2), fmt(_unnone(e["top_match_ci"][1]), 2),
                    e["chance_top_match"], "yes" if e["predicts"] else "no"))
    if not rows:
        return L + ["Not measured: no analysed run has `ablation.csv`.", ""]
    return L + ["| seed | movement | rollouts with ablation.csv | ticks | median ρ | top body part matches | chance | "
                "predicts |", "|---|---|---|---|---|---|---|---|"] + rows + [""]


def _unnone(x):
    return math.nan if x is None else x


def not_reproduced_section(found):
    """Every paper result the rule does not confirm, one line each."""
    L = ["## Paper results not reproduced", ""]
    missing = [f for f in found if f["verdict"] != "reproduced"]
    if not missing:
        return L + ["None: every finding holds by the rule.", ""]
    for f in missing:
        failed = ["%s %s seed %d (%s)" % (m, j, s, why) for m, j, s, holds, why, _ in f["checks"] if not holds]
        L.append("- (%s) %s: %s. Failing: %s." % (f["id"], f["title"], f["verdict"], "; ".join(failed)))
    return L + [""]


def reproduction_markdown(docs, command):
    seeds = sorted(docs)
    found = verdict.judge({s: seed_rows(docs[s]) for s in seeds})
    models = ["seed %d: %s" % (s, "; ".join("%s (%s)" % (m.get("path", "?"), m.get("checksum", "?"))
                                             for m in docs[s].get("models", []))) for s in seeds]
    L = ["# Reproduction: the paper's Table 2 and findings on its own protocol", "",
         "Generated from the Table 2 files of %d training seed(s) (do not edit by hand):" % len(seeds), "",
         "```", command, "```", "",
         "Each file comes from `toolchain/nao analyze` on the autonomous rollouts of one model:", ""]
    for s in seeds:
        L += ["```", "%s" % docs[s]["command"], "```", ""]
    L += ["Models: %s. How each seed's model and rollouts are made: docs/analysis.md, \"Regenerating "
          "docs/reproduction.md\" (seed 1 is models/autonomous.bin, its card models/autonomous.md; seed N's card is "
          "docs/reproduction/seed_N_model.md)." % " · ".join(models), "",
          "Paper: %s, sections 4.1–4.2, Table 2." % CITATION, ""]
    L += verdict_section(found, seeds)
    L += not_reproduced_section(found)
    L += paper_rows_section(docs)
    L += units_section(docs)
    L += mass_section(docs)
    L += ablation_section(docs)
    L += table_section(docs)
    return "\n".join(L).rstrip() + "\n"


def write_reproduction(paths, command, out=DOC):
    docs = load_seeds(paths)
    text = reproduction_markdown(docs, command)
    try:
        with open(out, "w") as f:
            f.write(text)
    except OSError as e:
        raise AnalysisError("%s: cannot write: %s" % (out, e.strerror)) from None
    return out, verdict.judge({s: seed_rows(docs[s]) for s in sorted(docs)})
