"""Prepared data sets (`toolchain/nao train data`, docs/formats.md): copying a demonstration."""
import os
import shutil

# What `nao_toolchain cluster` and training read from a demonstration's folder.
DEMONSTRATION_FILES = ("retarget.csv", "skeleton.csv", "calibration.json", "meta.json", ".done")


def copy_demonstration(src_dir, dst_dir):
    """Copies the demonstration in src_dir to dst_dir (created), ready for clustering."""
    os.makedirs(dst_dir, exist_ok=True)
    for f in DEMONSTRATION_FILES:
        if os.path.exists(os.path.join(src_dir, f)):
            shutil.copy(os.path.join(src_dir, f), dst_dir)
