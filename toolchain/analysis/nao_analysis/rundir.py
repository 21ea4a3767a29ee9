"""Read and validate one nao_rt run directory: ticks.csv, attention.bin, summary.json.

Formats: docs/nao_rt.md (ticks.csv, summary.json) and docs/attention_bin.md (attention.bin).
Everything is checked here, once, so that the statistics and figures never see a malformed
run: a problem raises AnalysisError with a message naming the file and what is wrong.
"""

import csv
import json
import os
from dataclasses import dataclass

import numpy as np

from . import N_JOINTS, AnalysisError

# ticks.csv columns the analysis reads (the timing columns are not needed).
_JOINT_COLUMNS = ("q_ref", "r", "a", "q_cmd", "q", "att")
REQUIRED_COLUMNS = (("tick", "t_s")
                    + tuple("%s_%d" % (c, j) for c in _JOINT_COLUMNS for j in range(N_JOINTS))
                    + ("ee_x", "ee_y", "ee_z", "ee_ref_x", "ee_ref_y", "ee_ref_z", "fault"))

# Fault bits (runtime/include/nao/controller.hpp, ControllerFault).
FAULT_NO_HUMAN = 1
FAULT_HUMAN_TIMEOUT = 2
FAULT_POLICY_NONFINITE = 16
# Ticks whose attention score is not the policy's answer to the tick's state: while returning
# home (human_timeout) the policy does not run at all; a non-finite action marks a broken
# inference. Ticks with only no_human keep running the policy on the held reference.
FAULTS_POLICY_BYPASSED = FAULT_HUMAN_TIMEOUT | FAULT_POLICY_NONFINITE

ATTENTION_MAGIC = b"NAOATTN1"
ATTENTION_HEADER = np.dtype([("magic", "S8"), ("version", "<u4"), ("header_bytes", "<u4"),
                             ("record_count", "<u8"), ("first_record", "<u8"), ("payload_bytes", "<u8"),
                             ("ring_capacity", "<u8"), ("records_written", "<u8"),
                             ("descriptor", "<u4", (8,)), ("reserved", "<u8")])
assert ATTENTION_HEADER.itemsize == 96


def attention_payload_dtype(n_layers, n_heads, n_tokens, d_model, window=0):
    """numpy dtype of one attention record (docs/attention_bin.md): payload format 2 (the
    temporal policy: mass per body part and the profile over `window` ages after the score) when
    window > 0, format 1 (the single-instant policy) when window == 0."""
    extra = [("mass", "<f4", (n_tokens,)), ("age_profile", "<f4", (window,))] if window else []
    data = 16 + 4 * (n_tokens + (n_tokens + window if window else 0) + n_layers * n_heads * n_tokens * n_tokens
                     + n_tokens * d_model)
    fields = ([("tick", "<u8"), ("fault", "<u4"), ("reserved", "<u4"), ("score", "<f4", (n_tokens,))] + extra
              + [("cross", "<f4", (n_layers, n_heads, n_tokens, n_tokens)), ("cross_out", "<f4", (n_tokens, d_model))])
    if data % 8:
        fields.append(("pad", "V%d" % (8 - data % 8)))
    return np.dtype(fields + [("checksum", "<u8")])


def fnv1a64_rows(rows):
    """FNV-1a 64 of every row of a (n, bytes) uint8 array, vectorised over the rows."""
    h = np.full(rows.shape[0], 0xCBF29CE484222325, dtype=np.uint64)
    prime = np.uint64(0x100000001B3)
    with np.errstate(over="ignore"):
        for col in range(rows.shape[1]):
            h = (h ^ rows[:, col].astype(np.uint64)) * prime  # uint64 arithmetic wraps mod 2^64
    return h


@dataclass(frozen=True)
class Attention:
    """attention.bin: header fields and one entry per record, oldest first."""
    n_layers: int
    n_heads: int
    n_tokens: int
    d_model: int
    first_record: int
    records_written: int
    ring_capacity: int
    tick: np.ndarray       # (n,) controller tick of each record
    fault: np.ndarray      # (n,) fault bits
    score: np.ndarray      # (n, T) per-body-part score, float32
    cross: np.ndarray      # (n, L, H, T, T) cross-attention alpha
    cross_out: np.ndarray  # (n, T, D) last decoder layer's cross-attention output
    window: int = 0                   # W of format 2 (0: format 1)
    mass: np.ndarray = None           # (n, T) raw cross-attention mass per body part (format 2)
    age_profile: np.ndarray = None    # (n, W) attention mass per age, 0 = the tick itself (format 2)


@dataclass(frozen=True)
class Run:
    """One validated run directory."""
    path: str
    movement: str
    summary: dict
    columns: dict          # ticks.csv column name -> float64 array (n_ticks,)
    attention: Attention

    @property
    def n_ticks(self):
        return len(self.columns["tick"])

    def joint_matrix(self, prefix):
        """(n_ticks, 5) array of the columns prefix_0 .. prefix_4."""
        return np.column_stack([self.columns["%s_%d" % (prefix, j)] for j in range(N_JOINTS)])

    def policy_mask(self):
        """True for ticks whose attention score is the policy's own output (not bypassed)."""
        fault = self.columns["fault"].astype(np.int64)
        finite = np.isfinite(self.joint_matrix("att")).all(axis=1) & np.isfinite(self.joint_matrix("q")).all(axis=1)
        return ((fault & FAULTS_POLICY_BYPASSED) == 0) & finite


def read_ticks(path):
    """ticks.csv -> {column: float64 array}. Raises AnalysisError naming the line at fault."""
    if not os.path.isfile(path):
        raise AnalysisError("%s: missing (not a nao_rt run directory?)" % path)
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        raise AnalysisError("%s: empty file" % path)
    header = [h.strip() for h in rows[0]]
    missing = [c for c in REQUIRED_COLUMNS if c not in header]
    if missing:
        raise AnalysisError("%s: missing column(s) %s" % (path, ", ".join(missing)))
    body = [r for r in rows[1:] if r]
    if not body:
        raise AnalysisError("%s: no ticks after the header" % path)
    values = np.empty((len(body), len(header)))
    for i, r in enumerate(body):
        if len(r) != len(header):
            raise AnalysisError("%s: line %d has %d fields, the header %d" % (path, i + 2, len(r), len(header)))
        try:
            values[i] = [float(x) for x in r]  # float() reads the runtime's "nan" too
        except ValueError as e:
            raise AnalysisError("%s: line %d: %s" % (path, i + 2, e)) from None
    columns = {h: values[:, k].copy() for k, h in enumerate(header)}
    tick, t_s = columns["tick"], columns["t_s"]
    if not np.array_equal(tick, np.arange(len(tick))):
        raise AnalysisError("%s: column tick is not 0, 1, 2, ... (ticks missing or out of order)" % path)
    # numpy.gradient over t_s needs distinct, increasing times.
    if not (np.isfinite(t_s).all() and np.all(np.diff(t_s) > 0)):
        raise AnalysisError("%s: column t_s is not finite and strictly increasing" % path)
    return columns


def read_attention(path):
    """attention.bin -> Attention, with every header field, size and record checksum checked."""
    if not os.path.isfile(path):
        raise AnalysisError("%s: missing (not a nao_rt run directory?)" % path)
    raw = np.fromfile(path, dtype=np.uint8)
    if raw.size < ATTENTION_HEADER.itemsize:
        raise AnalysisError("%s: truncated: %d bytes, shorter than the 96-byte header" % (path, raw.size))
    h = raw[:ATTENTION_HEADER.itemsize].view(ATTENTION_HEADER)[0]
    if bytes(h["magic"]) != ATTENTION_MAGIC:
        raise AnalysisError("%s: bad magic %r (expected %r): not an attention.bin"
                            % (path, bytes(h["magic"]), ATTENTION_MAGIC))
    if int(h["version"]) != 1:
        raise AnalysisError("%s: version %d, this analysis reads version 1" % (path, int(h["version"])))
    fmt, n_layers, n_heads, n_tokens, d_model, window = (int(v) for v in h["descriptor"][:6])
    if fmt not in (1, 2):
        raise AnalysisError("%s: payload format %d, this analysis reads formats 1 and 2" % (path, fmt))
    if fmt == 1:
        window = 0
    elif window < 1:
        raise AnalysisError("%s: payload format 2 with window %d: expected a positive window" % (path, window))
    if n_tokens != N_JOINTS or min(n_layers, n_heads, d_model) < 1:
        raise AnalysisError("%s: descriptor L=%d H=%d T=%d D=%d: expected T=%d and positive L, H, D"
                            % (path, n_layers, n_heads, n_tokens, d_model, N_JOINTS))
    rec = attention_payload_dtype(n_layers, n_heads, n_tokens, d_model, window)
    if int(h["payload_bytes"]) != rec.itemsize:
        raise AnalysisError("%s: payload_bytes %d, the descriptor implies %d"
                            % (path, int(h["payload_bytes"]), rec.itemsize))
    start, count = int(h["header_bytes"]), int(h["record_count"])
    if start < ATTENTION_HEADER.itemsize:
        raise AnalysisError("%s: header_bytes %d < 96" % (path, start))
    need = start + count * rec.itemsize
    if raw.size < need:
        raise AnalysisError("%s: truncated: %d bytes, the header announces %d records (%d bytes)"
                            % (path, raw.size, count, need))
    if int(h["records_written"]) < int(h["first_record"]) + count:
        raise AnalysisError("%s: records_written %d < first_record %d + record_count %d"
                            % (path, int(h["records_written"]), int(h["first_record"]), count))
    body = raw[start:need]
    records = body.view(rec)
    if count:
        sums = fnv1a64_rows(body.reshape(count, rec.itemsize)[:, :rec.itemsize - 8])
        bad = np.flatnonzero(sums != records["checksum"])
        if bad.size:
            raise AnalysisError("%s: record %d (and %d more) fails its FNV-1a checksum: corrupt file"
                                % (path, int(h["first_record"]) + int(bad[0]), bad.size - 1))
    return Attention(n_layers=n_layers, n_heads=n_heads, n_tokens=n_tokens, d_model=d_model,
                     first_record=int(h["first_record"]), records_written=int(h["records_written"]),
                     ring_capacity=int(h["ring_capacity"]), tick=records["tick"].astype(np.int64),
                     fault=records["fault"].astype(np.int64), score=records["score"].copy(),
                     cross=records["cross"].copy(), cross_out=records["cross_out"].copy(), window=window,
                     mass=records["mass"].copy() if window else None,
                     age_profile=records["age_profile"].copy() if window else None)


def read_summary(path):
    if not os.path.isfile(path):
        raise AnalysisError("%s: missing (not a nao_rt run directory?)" % path)
    try:
        with open(path) as f:
            summary = json.load(f)
    except (ValueError, UnicodeDecodeError) as e:
        raise AnalysisError("%s: not valid JSON: %s" % (path, e)) from None
    if not isinstance(summary, dict) or not isinstance(summary.get("movement"), str) or not summary["movement"]:
        raise AnalysisError("%s: no \"movement\" name" % path)
    return summary


def read_run(path):
    """Reads and cross-checks a run directory. Raises AnalysisError on any problem."""
    if not os.path.isdir(path):
        raise AnalysisError("%s: not a directory" % path)
    columns = read_ticks(os.path.join(path, "ticks.csv"))
    attention = read_attention(os.path.join(path, "attention.bin"))
    summary = read_summary(os.path.join(path, "summary.json"))
    n = len(columns["tick"])
    # The two files must describe the same run: same ticks, same fault bits, same scores.
    tick = attention.tick
    if tick.size and (tick.min() < 0 or tick.max() >= n or np.any(np.diff(tick) != 1)):
        raise AnalysisError("%s: attention.bin records ticks %d..%d, ticks.csv has 0..%d"
                            % (path, int(tick.min()), int(tick.max()), n - 1))
    att = np.column_stack([columns["att_%d" % j] for j in range(N_JOINTS)])[tick].astype(np.float32)
    same = (att == attention.score) | (np.isnan(att) & np.isnan(attention.score))
    if not same.all() or not np.array_equal(columns["fault"][tick].astype(np.int64), attention.fault):
        first = int(tick[np.flatnonzero(~same.all(axis=1) | (columns["fault"][tick] != attention.fault))[0]])
        raise AnalysisError("%s: attention.bin and ticks.csv disagree at tick %d (scores or fault bits): "
                            "files from different runs?" % (path, first))
    return Run(path=os.path.abspath(path), movement=summary["movement"], summary=summary,
               columns=columns, attention=attention)
