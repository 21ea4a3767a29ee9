#!/usr/bin/env python3
"""The repository stands alone: no file cites design notes that a user's clone does not have.

usage: standalone_text.py SOURCE_DIR

Greps every text file of the repository (in a git checkout: the tracked files and the untracked
ones git does not ignore; elsewhere: a walk that skips .git, build trees and out/) for citations
of outside design notes. What a reader needs is said where it is needed, or in docs/
(docs/architecture.md). Exit 0 when nothing matches, 1 with one `file:line: text` per match.
"""
import os
import re
import subprocess
import sys

# Built from pieces so that this file does not match its own pattern.
NOTES = ("DES" + "IGN", "STY" + "LE")
PATTERN = re.compile("|".join([
    NOTES[0] + " \u00a7",          # "<notes> §N"
    NOTES[0] + " section",         # "<notes> section N"
    NOTES[1] + " [0-9]",           # "<notes> N"
    NOTES[0] + r"\.md",
    NOTES[1] + r"\.md",
]))
SKIP_DIRS = re.compile(r"^(\.git|build|build-.*|out|__pycache__)$")


def repository_files(root):
    """Paths relative to root: git's view when root is a checkout, else a walk."""
    try:
        out = subprocess.run(["git", "-C", root, "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
                             check=True, capture_output=True).stdout
        top = subprocess.run(["git", "-C", root, "rev-parse", "--show-toplevel"], check=True,
                             capture_output=True, text=True).stdout.strip()
        if os.path.realpath(top) == os.path.realpath(root):
            return sorted(p.decode("utf-8", "replace") for p in out.split(b"\0") if p)
    except (OSError, subprocess.CalledProcessError):
        pass
    files = []
    for d, dirs, names in os.walk(root):
        dirs[:] = sorted(x for x in dirs if not SKIP_DIRS.match(x))
        files += [os.path.relpath(os.path.join(d, n), root) for n in names]
    return sorted(files)


def main():
    if len(sys.argv) != 2:
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    root = sys.argv[1]
    found = []
    n_files = 0
    for rel in repository_files(root):
        path = os.path.join(root, rel)
        if not os.path.isfile(path) or os.path.islink(path):
            continue
        with open(path, "rb") as f:
            data = f.read()
        if b"\0" in data[:8192]:
            continue  # binary
        n_files += 1
        for i, line in enumerate(data.decode("utf-8", "replace").splitlines(), 1):
            if PATTERN.search(line):
                found.append(f"{rel}:{i}: {line.strip()[:160]}")
    if found:
        print(f"{len(found)} line(s) cite design notes outside the repository; say the point or name a docs/ "
              f"page instead (docs/architecture.md):")
        print("\n".join(found))
        return 1
    print(f"{n_files} text files, no citation of outside design notes")
    return 0


if __name__ == "__main__":
    sys.exit(main())
