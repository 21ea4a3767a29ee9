"""docs/reproduction.md from the Table 2 files of several training seeds
(`toolchain/nao analyze --reproduction-from docs/reproduction/seed_*.json`).

Everything in the page comes from the JSON files (table_json.py), so the page is remade by one
command from committed numbers; hand edits would be lost. What a file of an older schema lacks
(the groupings at other thresholds, the ablation's per-run counts, the robustness variants,
p-values read off the intervals) is written as "not in this file", and no verdict that needs it
is drawn.
"""

import math
import os

from . import JOINT_NAMES, AnalysisError
from . import ablation, stats, verdict
from .paper import CITATION, PAPER_FINDINGS, PAPER_MI_CLAIMS, PAPER_TABLE2, paper_row
from .report import fmt, fmt_p
from .table_json import p_values_agree_with_intervals, read_table_json, row_from_json
from .units import ROBUSTNESS_DTW_M, UNIT_DTW_M

REPO = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", ".."))
DOC = os.path.join(REPO, "docs", "reproduction.md")
MOVEMENTS = ("whole_arm", "elbow", "wrist")
NOT_IN_FILE = "not in this file"
DEFAULT_DETREND = "linear"
# The robustness columns: (label, unit_dtw_m, detrend name); the analysis default is 1 mm, linear.
VARIANTS = tuple(("%g mm" % (1e3 * t), t, DEFAULT_DETREND) for t in ROBUSTNESS_DTW_M) + (
    ("detrend none", UNIT_DTW_M, "none"), ("detrend highpass", UNIT_DTW_M, "highpass"))


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
    return _rows(doc["table2"], score)


def _rows(table, score=verdict.SCORE):
    return {(o["movement"], o["joint"]): row_from_json(o) for o in table.get(score, [])}


def variant_rows(doc, unit_dtw_m, detrend_name):
    """{(movement, joint): row} of the document's Table 2 at a distinct-rollout threshold and a
    trend removal (by name: highpass at any cutoff), or None when the file does not hold it."""
    method = doc["method"]
    if method.get("unit_dtw_m") == unit_dtw_m and stats.parse_detrend(method["detrend"])[0] == detrend_name:
        return seed_rows(doc)
    for v in doc.get("variants", []):
        if v["unit_dtw_m"] == unit_dtw_m and stats.parse_detrend(v["detrend"])[0] == detrend_name:
            return _rows(v["table2"])
    return None


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


def _rule_head(title, criterion, seeds, what):
    L = ["## " + title, "", "Criterion: " + criterion, ""]
    if len(seeds) < verdict.N_SEEDS:
        L += ["Seeds analysed: %s, fewer than the rule's %d: no %s can be *reproduced* here."
              % (", ".join(str(s) for s in seeds), verdict.N_SEEDS, what), ""]
    return L


def verdict_section(found, seeds):
    L = _rule_head("The paper's findings, by the rule", verdict.CRITERION, seeds, "finding")
    for f in found:
        L += ["### (%s) %s: **%s**" % (f["id"], f["title"], f["verdict"]), "",
              "Paper (§4.2): %s" % f["paper"], "",
              "%d of %d (row, seed) pairs hold." % (f["n_held"], f["n_needed"]), "",
              "| movement | joint | paper ρ | seed | our ρ [95 % interval] | holds |", "|---|---|---|---|---|---|"]
        for movement, joint, seed, holds, why, row in f["checks"]:
            rho = paper_row(movement, joint)[4]
            L.append("| %s | %s | %.2f | %d | %s | %s |" % (movement, joint, rho, seed,
                                                           _ci(row, "spearman_rho") if row else "–",
                                                           "yes" if holds else "no: " + why))
        L.append("")
    return L


def _mi_check_cell(row):
    if row is None:
        return "–"
    return "%s (q95 %s; excess over q95 %s)" % (fmt(row["mi_bits"], 2), fmt(row["mi_null_q95"], 2),
                                                 _signed(verdict.mi_excess_q95(row)))


def _signed(x, digits=2):
    return "–" if not math.isfinite(x) else "%+.*f" % (digits, x)


def mi_section(found_mi, seeds):
    L = _rule_head("The paper's MI statements, against the null", verdict.MI_CRITERION, seeds, "statement")
    for f in found_mi:
        ours = [c[-1]["mi_bits"] for c in f["checks"] if c[-1] is not None and math.isfinite(c[-1]["mi_bits"])]
        paper = [paper_row(c[0], c[1])[7] for c in f["checks"]]
        below = ours and max(ours) < 1
        L += ["### (%s) MI: **%s**%s" % (f["id"], f["verdict"], " against the null; the paper's magnitude is not"
                                          if below and f["verdict"] != "not reproduced" else ""), "",
              "Paper (§4.2): %s" % f["statement"], "",
              "%d of %d (check, seed) pairs hold." % (f["n_held"], f["n_needed"]), ""]
        if ours:
            L += ["The magnitude is not the paper's: our MI is %.2f–%.2f bits where the paper has %.2f–%.2f; %s "
                  "reaches the paper's 1 bit." % (min(ours), max(ours), min(paper), max(paper),
                                                   "none" if below else "some"), ""]
        L += ["| movement | joint | check | paper MI [bits] | seed | our MI [bits] | holds |",
              "|---|---|---|---|---|---|---|"]
        for movement, joint, kind, seed, holds, why, row in f["checks"]:
            mi = paper_row(movement, joint)[7]
            L.append("| %s | %s | %s | %.2f | %d | %s | %s |" % (
                movement, joint, "largest of the movement" if kind == "largest" else "above the null", mi, seed,
                _mi_check_cell(row), "yes" if holds else "no: " + why))
        L.append("")
    return L


def _verdict_over(docs, seeds, key, judge):
    """judge's verdicts over the seeds, on the Table 2 of variant key (label, unit_dtw_m, detrend)."""
    return judge({s: variant_rows(docs[s], key[1], key[2]) for s in seeds})


def robustness_section(docs):
    seeds = sorted(docs)
    have = {key: [s for s in seeds if variant_rows(docs[s], key[1], key[2]) is not None] for key in VARIANTS}
    common = [s for s in seeds if all(s in have[k] for k in VARIANTS)]
    lacking = [s for s in seeds if s not in common]
    L = ["## Does a verdict hinge on a choice?", "",
         "The same rules on Table 2 computed with other choices: runs grouped into distinct rollouts at %s "
         "(complete linkage; trend removal linear), and with the trend removal `none` or `highpass` (0.1 Hz) "
         "at 1 mm. Only the choice named in a column differs from the default (1 mm, linear)."
         % ", ".join("%g mm" % (1e3 * t) for t in ROBUSTNESS_DTW_M), ""]
    if lacking:
        L += ["Seed%s %s: %s (%s the default analysis only)." % (
            "s" if len(lacking) > 1 else "", ", ".join(str(s) for s in lacking), NOT_IN_FILE,
            "their files hold" if len(lacking) > 1 else "its file holds"), ""]
    if not common:
        return L + ["No seed's file holds every variant: nothing to compare.", ""]
    L += ["Verdicts over seed%s %s, the seeds whose files hold every variant%s:" % (
        "s" if len(common) > 1 else "", ", ".join(str(s) for s in common),
        "; with fewer than %d seeds no verdict can read *reproduced*" % verdict.N_SEEDS
        if len(common) < verdict.N_SEEDS else ""), "",
          "| finding | statement | %s | changes with the threshold | changes with the trend removal |"
          % " | ".join(k[0] for k in VARIANTS), "|---|---|%s---|---|" % ("---|" * len(VARIANTS))]
    changed = []
    for label, judge in (("ρ rule", verdict.judge), ("MI", verdict.judge_mi)):
        by_key = {k: _verdict_over(docs, common, k, judge) for k in VARIANTS}
        for i, f in enumerate(by_key[VARIANTS[0]]):
            v = {k: by_key[k][i]["verdict"] for k in VARIANTS}
            thresholds = {v[k] for k in VARIANTS if k[2] == DEFAULT_DETREND}
            trends = {v[k] for k in VARIANTS if k[1] == UNIT_DTW_M}
            for what, vs in (("threshold", thresholds), ("trend removal", trends)):
                if len(vs) > 1:
                    changed.append("(%s) %s changes with the %s" % (f["id"], label, what))
            L.append("| (%s) | %s | %s | %s | %s |" % (f["id"], label, " | ".join(v[k] for k in VARIANTS),
                                                      "yes" if len(thresholds) > 1 else "no",
                                                      "yes" if len(trends) > 1 else "no"))
    L += ["", ("A verdict that changes: %s." % "; ".join(changed)) if changed else
          "No verdict changes with the threshold or the trend removal.", ""]
    L += ["Each (row, seed) of the ρ rule under every choice: Spearman ρ [95 % interval], ✓ where the row holds.",
          "", "| movement | joint | seed | %s |" % " | ".join(k[0] for k in VARIANTS),
          "|---|---|---|%s" % ("---|" * len(VARIANTS))]
    for *_, pairs in PAPER_FINDINGS:
        for movement, joint in pairs:
            sign = verdict.paper_sign(movement, joint)
            for s in seeds:
                cells = []
                for k in VARIANTS:
                    rows = variant_rows(docs[s], k[1], k[2])
                    r = None if rows is None else rows.get((movement, joint))
                    cells.append(NOT_IN_FILE if r is None else "%s %s" % (
                        _ci(r, "spearman_rho"), "✓" if verdict.row_holds(r, sign)[0] else "✗"))
                L.append("| %s | %s | %d | %s |" % (movement, joint, s, " | ".join(cells)))
    L += ["", "Each (check, seed) of the MI statements under every choice: the MI's excess over its null's 95 % "
          "quantile [bits], ✓ where the check holds.", "",
          "| movement | joint | check | seed | %s |" % " | ".join(k[0] for k in VARIANTS),
          "|---|---|---|---|%s" % ("---|" * len(VARIANTS))]
    for fid, *_ in PAPER_FINDINGS:
        for movement, joint, kind in PAPER_MI_CLAIMS[fid][1]:
            for s in seeds:
                cells = []
                for k in VARIANTS:
                    rows = variant_rows(docs[s], k[1], k[2])
                    if rows is None or (movement, joint) not in rows:
                        cells.append(NOT_IN_FILE)
                        continue
                    cells.append("%s %s" % (_signed(verdict.mi_excess_q95(rows[(movement, joint)])),
                                            "✓" if verdict.mi_holds(rows, movement, joint, kind)[0] else "✗"))
                L.append("| %s | %s | %s | %d | %s |" % (movement, joint, kind, s, " | ".join(cells)))
    return L + [""]


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


def _groupings(entry):
    """{unit_dtw_m: grouping} of a movement entry of the JSON (none in schema 1)."""
    return {g["unit_dtw_m"]: g for g in entry.get("groupings", [])}


def units_section(docs):
    L = ["## Runs and distinct rollouts", "",
         "One autonomous rollout per held-out demonstration (its s_0, its length). Runs whose hand paths all lie "
         "within the threshold of each other (DTW mean distance over their common ticks; complete linkage, so "
         "no chain of near neighbours joins runs farther apart) repeat one rollout and form one unit; each unit "
         "enters the statistics once (its longest run), and the bootstrap draws units. The default threshold is "
         "%s mm; the unit counts at %s show how much rests on it. The DTW columns are at the default threshold."
         % (fmt(1e3 * UNIT_DTW_M, 1), ", ".join("%g mm" % (1e3 * t) for t in ROBUSTNESS_DTW_M)), ""]
    single = [s for s in sorted(docs) if docs[s]["method"].get("unit_grouping") != "complete linkage"]
    if single:
        L += ["Seed%s %s: the file's units come from a transitive grouping (a run within the threshold of any run "
              "of a unit joins it), so two runs of one unit can lie farther apart than runs of different units; "
              "the other thresholds are %s." % ("s" if len(single) > 1 else "", ", ".join(str(s) for s in single),
                                                NOT_IN_FILE), ""]
    L += ["| seed | movement | runs | %s | largest DTW inside a unit [mm] | smallest DTW between units [mm] |"
          % " | ".join("units at %g mm" % (1e3 * t) for t in ROBUSTNESS_DTW_M),
          "|---|---|---|%s---|---|" % ("---|" * len(ROBUSTNESS_DTW_M))]
    for s in sorted(docs):
        mv = docs[s]["movements"]
        threshold = docs[s]["method"].get("unit_dtw_m")
        for m in _ordered(mv):
            e = mv[m]
            g = _groupings(e)
            counts = [str(g[t]["n_units"]) if t in g else str(e["n_units"]) if t == threshold else NOT_IN_FILE
                      for t in ROBUSTNESS_DTW_M]
            L.append("| %d | %s | %d | %s | %s | %s |" % (
                s, m, e["n_runs"], " | ".join(counts), _mm(e.get("max_dtw_within_unit_m")),
                _mm(e.get("min_dtw_between_units_m"))))
    return L + [""]


def _mm(x):
    return "–" if x is None else "%.3f" % (1e3 * x)


def contradictions(rows):
    """(movement, joint, statistic) of every correlation whose p-value and 95 % interval disagree
    (p < 0.05 while the interval holds 0, or p >= 0.05 while it excludes 0), and the number of
    cells checked."""
    bad, n = [], 0
    for (m, j), r in sorted(rows.items()):
        for name in stats.STAT_NAMES[:3]:
            p, lo, hi = r[name + "_p"], r[name + "_ci_lo"], r[name + "_ci_hi"]
            if not (math.isfinite(p) and math.isfinite(lo) and math.isfinite(hi)):
                continue
            n += 1
            if (p < 0.05) != (lo > 0 or hi < 0):
                bad.append((m, j, name))
    return bad, n


def table_section(docs):
    L = ["## Table 2, every joint, per seed", "",
         "Norm-based score `att_j` (the raw mass `attm_j` is in the JSON files). Each correlation: estimate [95 % "
         "interval over distinct rollouts], p-value read off the same bootstrap (p < 0.05 exactly when the "
         "interval excludes 0). MI: estimate, its circular-shift null (median, 95 % quantile) and the excess over "
         "the median; an MI is evidence of dependence only above the null's 95 % quantile.", ""]
    old = [s for s in sorted(docs) if not p_values_agree_with_intervals(docs[s])]
    if old:
        L += ["Seed%s %s: the file's p-values come from a permutation test that holds the set of rollouts fixed, "
              "so they can contradict the intervals; they are not shown (p-values read off the intervals: %s)."
              % ("s" if len(old) > 1 else "", ", ".join(str(s) for s in old), NOT_IN_FILE), ""]
    for s in sorted(docs):
        rows = seed_rows(docs[s])
        shown = s not in old
        L += ["### Seed %d" % s, ""]
        if shown:
            for prefix in sorted(docs[s]["table2"]):
                bad, n = contradictions(_rows(docs[s]["table2"], prefix))
                L.append("p-values that contradict their own interval (`%s`): %d of %d%s." % (
                    prefix, len(bad), n, "" if not bad else ": " + "; ".join("%s %s %s" % b for b in bad)))
            L.append("")
        L += ["| movement | joint | Pearson r | Spearman ρ | Kendall τ-b | MI [bits] | runs / units | ticks |",
              "|---|---|---|---|---|---|---|---|"]
        for m in _ordered({k[0] for k in rows}):
            for j in JOINT_NAMES:
                r = rows.get((m, j))
                if r is None:
                    continue
                cells = [(_cell if shown else _ci)(r, c) for c in ("pearson_r", "spearman_rho", "kendall_tau")]
                L.append("| %s | %s | %s | %s | %d / %d | %d |" % (
                    m, j, " | ".join(cells), _mi_cell(r), r["n_runs"], r["n_units"], r["n_ticks"]))
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


def ablation_at(doc, movement, unit_dtw_m):
    """The ablation summary (ablation.summary_from_records) of one movement with the runs grouped
    at unit_dtw_m, recomputed from the file's per-run counts with its bootstrap and seed; None
    when the file lacks the counts or that grouping."""
    records = doc.get("ablation_runs", {}).get(movement)
    g = _groupings(doc["movements"].get(movement, {})).get(unit_dtw_m)
    if records is None or g is None:
        return None
    method = doc["method"]
    return ablation.summary_from_records([records[u[0]] for u in g["units"]], method["bootstrap"],
                                         method["analysis_seed"])


def _est_ci(value, ci):
    return "%s [%s, %s]" % (fmt(value, 2), fmt(_unnone(ci[0]), 2), fmt(_unnone(ci[1]), 2))


def ablation_section(docs):
    L = ["## Attention against ablation", "",
         "Per tick, Spearman ρ between the five body parts' attention masses and how far masking each body part "
         "(its cross-attention logits set to −∞ in every decoder layer over the whole window) moves the executed "
         "action (`ablation.csv`); the median over ticks. And how often the most-attended body part is the one "
         "whose masking moves the action most (the match rate), against its chance level: the rate if the "
         "attention's pick and the ablation's were independent, Σ_j P(attention picks j) · P(masking j moves the "
         "action most), per seed and movement. A uniform 1/5 would be too low where both favour the same body "
         "part and too high where they favour different ones. 95 % intervals from one bootstrap over distinct "
         "rollouts: the match rate is *above chance* only when the interval of match rate − chance level, both "
         "recomputed on the same resampled rollouts, lies above 0; attention *predicts* the ablation only when, "
         "besides, the median ρ's interval lies above 0. Columns at the default threshold (1 mm), the last two at "
         "each threshold.", ""]
    rows, counted = [], {t: [0, 0, 0] for t in ROBUSTNESS_DTW_M}
    for s in sorted(docs):
        ab = docs[s].get("ablation") or {}
        for m in _ordered(ab):
            e = ab[m]
            if not e:
                continue
            at = {t: ablation_at(docs[s], m, t) for t in ROBUSTNESS_DTW_M}
            for t, a in at.items():
                if a is not None:
                    counted[t][0] += 1
                    counted[t][1] += a["above_chance"]
                    counted[t][2] += a["predicts"]
            has_chance = "chance" in e
            rows.append("| %d | %s | %d of %d | %d | %s | %s | %s | %s | %s | %s |" % (
                s, m, e["n_units"], e["n_units_total"], e["n_ticks"], _est_ci(e["rho_median"], e["rho_ci"]),
                _est_ci(e["top_match_rate"], e["top_match_ci"]),
                _est_ci(e["chance"], e["chance_ci"]) if has_chance else NOT_IN_FILE,
                _est_ci(e["excess"], e["excess_ci"]) if has_chance else "–",
                " / ".join(NOT_IN_FILE if a is None else "yes" if a["above_chance"] else "no" for a in at.values()),
                " / ".join(NOT_IN_FILE if a is None else "yes" if a["predicts"] else "no" for a in at.values())))
    if not rows:
        return L + ["Not measured: no analysed run has `ablation.csv`.", ""]
    L += ["| seed | movement | rollouts with ablation.csv | ticks | median ρ | match rate | chance level | "
          "match − chance | above chance at %s | predicts at %s |" % ((" / ".join(
              "%g" % (1e3 * t) for t in ROBUSTNESS_DTW_M) + " mm",) * 2),
          "|---|---|---|---|---|---|---|---|---|---|"] + rows + [""]
    for t in ROBUSTNESS_DTW_M:
        n, above, predicts = counted[t]
        L.append("- At %g mm: %s" % (1e3 * t, "%d of %d (seed, movement) pairs with a chance level are above "
                                              "it; attention predicts the ablation (both rules) in %d of %d."
                                     % (above, n, predicts, n) if n else "no file holds the chance level."))
    return L + [""]


def _unnone(x):
    return math.nan if x is None else x


def not_reproduced_section(found, found_mi):
    """Every paper result the rules do not confirm, one line each."""
    L = ["## Paper results not reproduced", ""]
    missing = [(f, "") for f in found if f["verdict"] != "reproduced"]
    missing += [(f, "MI: ") for f in found_mi if f["verdict"] != "reproduced"]
    if not missing:
        return L + ["None: every finding and MI statement holds by the rules.", ""]
    titles = {f["id"]: f["title"] for f in found}
    for f, what in missing:
        failed = ["%s %s seed %d (%s)" % (c[0], c[1], c[-4], c[-2]) for c in f["checks"] if not c[-3]]
        if f["n_seeds"] < verdict.N_SEEDS:
            failed.append("%d of %d seeds analysed" % (f["n_seeds"], verdict.N_SEEDS))
        L.append("- (%s) %s%s: %s. Failing: %s." % (f["id"], what, titles[f["id"]], f["verdict"], "; ".join(failed)))
    return L + [""]


# The paper's Transformer (its section 3): what a table of another configuration is not.
PAPER_CONFIGURATION = "d_model 128, 4 heads, 4 + 4 layers, FFN 512 × 3"
CARD_ROWS = (("config", "config"), ("d_model / heads", "d_model / heads"), ("encoder / decoder layers", "layers"),
             ("window", "window"), ("parameters (manifest floats)", "parameters"))


def card_path(seed):
    """The model card of training seed `seed`, as the page's convention names it."""
    name = "autonomous.md" if seed == 1 else os.path.join("seeds", "seed_%d.md" % seed)
    return os.path.join(REPO, "models", name)


def model_configuration(seed):
    """The configuration rows of seed `seed`'s model card ("config small; d_model / heads 32 / 4; ..."),
    or None without a card. The Table 2 files do not carry the architecture; the card does."""
    try:
        with open(card_path(seed)) as f:
            rows = {}
            for line in f:
                cells = [c.strip() for c in line.strip().strip("|").split("|")]
                if len(cells) == 2:
                    rows.setdefault(cells[0], cells[1])
    except OSError:
        return None
    got = ["%s %s" % (label, rows[key].split(":")[0].split(" (")[0]) for key, label in CARD_ROWS if key in rows]
    return "; ".join(got) if got else None


def configuration_lines(seeds):
    L = ["Configuration of each seed's model (from its card, %s):" % ", ".join(
        os.path.relpath(card_path(s), REPO) for s in seeds), ""]
    for s in seeds:
        c = model_configuration(s)
        L.append("- seed %d: %s" % (s, c if c else "no card: not recorded"))
    L += ["", "The paper's model is %s. Tables from another configuration measure the paper's "
          "analysis on a different net: a finding not reproduced there may be the net's size, not the "
          "finding." % PAPER_CONFIGURATION, ""]
    return L


def reproduction_markdown(docs, command):
    seeds = sorted(docs)
    found = verdict.judge({s: seed_rows(docs[s]) for s in seeds})
    found_mi = verdict.judge_mi({s: seed_rows(docs[s]) for s in seeds})
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
          "models/seeds/seed_N.md)." % " · ".join(models), "",
          "Paper: %s, sections 4.1–4.2, Table 2." % CITATION, ""]
    L += configuration_lines(seeds)
    L += verdict_section(found, seeds)
    L += mi_section(found_mi, seeds)
    L += robustness_section(docs)
    L += not_reproduced_section(found, found_mi)
    L += paper_rows_section(docs)
    L += units_section(docs)
    L += mass_section(docs)
    L += ablation_section(docs)
    L += table_section(docs)
    return "\n".join(L).rstrip() + "\n"


def write_reproduction(paths, command, out=DOC):
    """Writes the page; returns (its path, verdict.judge's findings, verdict.judge_mi's)."""
    docs = load_seeds(paths)
    text = reproduction_markdown(docs, command)
    try:
        with open(out, "w") as f:
            f.write(text)
    except OSError as e:
        raise AnalysisError("%s: cannot write: %s" % (out, e.strerror)) from None
    rows = {s: seed_rows(docs[s]) for s in sorted(docs)}
    return out, verdict.judge(rows), verdict.judge_mi(rows)
