"""Table 2 of one analysis as JSON (`toolchain/nao analyze --table-json FILE`): the input of
`--reproduction-from`, so docs/reproduction.md is made from committed numbers, one file per
training seed. Keys: docs/analysis.md "Table 2 as JSON".

Schema 2 adds what docs/reproduction.md needs beyond one Table 2: the runs' groupings into
distinct rollouts at every threshold (`movements.*.groupings`), each run's ablation counts
(`ablation_runs`), and Table 2 at other thresholds and trend removals (`variants`). Files of
schema 1 are still read; their correlation p-values come from a permutation test that holds
the set of rollouts fixed (`method.p_values`), which can contradict the intervals, and they
lack the keys above: the page says so where it needs them.
"""

import json
import math

from . import AnalysisError
from . import stats

SCHEMA = "nao-table2/2"
READABLE = ("nao-table2/1", SCHEMA)
# method.p_values of this schema: how the correlations' p-values were made.
P_FROM_INTERVAL = "bootstrap interval"
STAT_KEYS = ("estimate", "ci_lo", "ci_hi", "p")


def _num(x):
    """JSON number or null (NaN and infinities are not JSON)."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _unnum(x):
    return math.nan if x is None else float(x)


def row_json(r):
    """One Table 2 row (table2.COLUMNS dict) as a JSON object."""
    out = {"movement": r["movement"], "joint": r["joint"], "n_runs": int(r["n_runs"]), "n_units": int(r["n_units"]),
           "n_ticks": int(r["n_ticks"]), "n_dropped": int(r["n_dropped"]), "block_len": int(r["block_len"]),
           "n_shifts": int(r["n_shifts"]), "detrend": r["detrend"]}
    for s in stats.STAT_NAMES:
        out[s] = {"estimate": _num(r[s]), "ci_lo": _num(r[s + "_ci_lo"]), "ci_hi": _num(r[s + "_ci_hi"]),
                  "p": _num(r[s + "_p"])}
    out["mi_bits"].update({"null_median": _num(r["mi_null_median"]), "null_q95": _num(r["mi_null_q95"]),
                           "excess": _num(r["mi_excess"]), "above_null_q95": bool(r["mi_above_null"])})
    return out


def row_from_json(o):
    """The inverse of row_json: a table2.COLUMNS-style dict (nan for null)."""
    r = {k: o[k] for k in ("movement", "joint", "n_runs", "n_units", "n_ticks", "n_dropped", "block_len",
                           "n_shifts", "detrend")}
    for s in stats.STAT_NAMES:
        v = o[s]
        r[s], r[s + "_ci_lo"], r[s + "_ci_hi"], r[s + "_p"] = (_unnum(v[k]) for k in STAT_KEYS)
    mi = o["mi_bits"]
    r["mi_null_median"], r["mi_null_q95"], r["mi_excess"] = (_unnum(mi[k]) for k in ("null_median", "null_q95",
                                                                                      "excess"))
    r["mi_above_null"] = int(bool(mi["above_null_q95"]))
    return r


def table_document(training_seed, models, options, command, movements, rows_by_prefix, offsets, mass, ablation,
                   ablation_runs=None, variants=()):
    """The whole JSON document as a dict (write_table_json writes it). ablation_runs: {movement:
    {run directory name: ablation.run_record or None}}; variants: dicts {unit_dtw_m, detrend,
    table2: {prefix: rows}}."""
    return {
        "schema": SCHEMA,
        "training_seed": training_seed,
        "models": models,
        "command": command,
        "method": {"detrend": options["detrend"], "bootstrap": options["bootstrap"], "analysis_seed": options["seed"],
                   "ksg_k": stats.KSG_K, "permutations": options.get("permutations"),
                   "unit_dtw_m": options.get("unit_dtw_m"), "unit_grouping": "complete linkage",
                   "resampling_unit": options.get("resampling_unit"), "p_values": P_FROM_INTERVAL},
        "movements": movements,
        "table2": {p: [row_json(r) for r in rows] for p, rows in rows_by_prefix.items()},
        "attention_offsets": offsets,
        "attention_mass": mass,
        "ablation": ablation,
        "ablation_runs": ablation_runs or {},
        "variants": [{"unit_dtw_m": v["unit_dtw_m"], "detrend": v["detrend"],
                      "table2": {p: [row_json(r) for r in rows] for p, rows in v["table2"].items()}} for v in variants],
    }


def p_values_agree_with_intervals(doc):
    """True when the document's correlation p-values are read off their intervals' resamples."""
    return doc["method"].get("p_values") == P_FROM_INTERVAL


def json_ready(x):
    """NaN -> null all the way down (json.dumps would write the non-JSON NaN)."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: json_ready(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [json_ready(v) for v in x]
    return x


def write_table_json(path, doc):
    try:
        with open(path, "w") as f:
            json.dump(json_ready(doc), f, indent=1, ensure_ascii=False, allow_nan=False)
            f.write("\n")
    except OSError as e:
        raise AnalysisError("%s: cannot write: %s" % (path, e.strerror)) from None


def read_table_json(path):
    """A document written by write_table_json. Raises AnalysisError naming the file and what is wrong."""
    try:
        with open(path) as f:
            doc = json.load(f)
    except OSError as e:
        raise AnalysisError("%s: cannot read: %s" % (path, e.strerror)) from None
    except (ValueError, UnicodeDecodeError) as e:
        raise AnalysisError("%s: not valid JSON: %s" % (path, e)) from None
    if not isinstance(doc, dict) or doc.get("schema") not in READABLE:
        raise AnalysisError("%s: not a Table 2 file of schema %s (toolchain/nao analyze --table-json)"
                            % (path, " or ".join(READABLE)))
    try:
        for table in [doc["table2"]] + [v["table2"] for v in doc.get("variants", [])]:
            for rows in table.values():
                for o in rows:
                    row_from_json(o)
        doc["movements"].items()
        doc["method"].get("unit_dtw_m")
    except (KeyError, TypeError, AttributeError, ValueError) as e:
        raise AnalysisError("%s: malformed Table 2 file (%s: %s)" % (path, type(e).__name__, e)) from None
    return doc
