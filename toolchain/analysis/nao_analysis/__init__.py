"""Attention–motion analysis of nao_rt run directories (docs/analysis.md).

Modules, one topic each:
  rundir      read and validate a run directory (ticks.csv, attention.bin, summary.json)
  kinematics  forward kinematics of the NAO right arm from the URDF (stick figures, hand paths)
  stats       trend removal, Pearson/Spearman/Kendall tau-b, KSG mutual information,
              block length, circular block bootstrap, circular-shift permutation test
  table2      the paper's Table 2 for every movement x joint, with intervals and p-values
  figures     paper Figs. 8-16 and the UMAP of the cross-attention outputs
  report      table2.md and the self-contained report.html
  paper       the paper's own Table 2 numbers, for docs/reproduction.md
  cli         `toolchain/nao analyze`
  dataset     copying a prepared data set's demonstration (the data-set scripts beside the package)
"""

JOINT_NAMES = ("RShoulderPitch", "RShoulderRoll", "RElbowYaw", "RElbowRoll", "RWristYaw")
N_JOINTS = len(JOINT_NAMES)


class AnalysisError(Exception):
    """A problem the user can act on (bad run directory, bad option); printed as one line."""
