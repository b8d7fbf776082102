"""The repository stands alone and stays tidy: no file points outside it (the papers' digest or the papers
live elsewhere, their content is restated in docs/), MuJoCo's log is not committed, the typing marker the
package declares exists, and every experiment has a docs page linked from the README."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SKIP_DIRS = {".git", ".venv", "outputs", "__pycache__", ".pytest_cache", ".ruff_cache", "build", "dist"}
TEXT_SUFFIXES = {".py", ".md", ".yaml", ".yml", ".toml", ".mk", ".txt", ".cfg", ".ini", ".sh"}
# built from pieces so that this file does not match itself: the sibling folder, the papers and their digest
_DIGEST = "S" + "P" + "EC"
FORBIDDEN = ["../" + "shared", "shared/" + "papers", _DIGEST + ".md", _DIGEST + " §"]
EXPERIMENTS = ["cgail", "srb", "com-cnn", "motion-matching", "hopper-ga"]


def _text_files():
    for path in REPO.rglob("*"):
        rel = path.relative_to(REPO)
        if any(part in SKIP_DIRS or part.endswith(".egg-info") for part in rel.parts):
            continue
        if path.is_file() and (path.suffix in TEXT_SUFFIXES or path.name == "Makefile"):
            yield path


def test_no_file_refers_outside_the_repository():
    hits = []
    for path in _text_files():
        text = path.read_text(errors="replace")
        for n, line in enumerate(text.splitlines(), 1):
            hits += [f"{path.relative_to(REPO)}:{n}: {word!r}" for word in FORBIDDEN if word in line]
    assert not hits, "references to files outside the repository:\n" + "\n".join(hits)


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_every_experiment_has_a_self_contained_page_linked_from_the_readme(name):
    page = REPO / "docs" / f"{name}.md"
    text = page.read_text()
    for section in ("## The method", "## The paper's numbers"):
        assert section in text, f"{page.name} has no '{section}' section"
    assert "$$" in text, f"{page.name} states no equation"
    assert f"(docs/{name}.md)" in (REPO / "README.md").read_text()


def test_mujoco_log_is_not_committed_and_the_typing_marker_exists():
    assert "MUJOCO_LOG.TXT" in (REPO / ".gitignore").read_text().split()
    if (REPO / ".git").exists() and shutil.which("git"):
        tracked = subprocess.run(["git", "ls-files", "MUJOCO_LOG.TXT"], cwd=REPO, capture_output=True, text=True).stdout
        assert not tracked.strip(), "MUJOCO_LOG.TXT is committed"
    assert (REPO / "charctl" / "py.typed").is_file()
