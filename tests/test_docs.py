"""The documentation as a newcomer meets it: README.md and docs/*.md.

- every relative link resolves (files and #anchors);
- README.md is a front page (at most README_MAX_CHARS characters) that opens with the two
  make commands, and its results table agrees with the published summaries;
- every command in a ```bash block runs successfully as a real process, in a scratch folder,
  except those marked as too expensive (``# slow``) or as needing something the repository
  does not have (``# needs: ...``); a ```python block whose first line is ``# file: NAME``
  is written to that file in the scratch folder first (the task plugin of adding-a-task.md);
- docs/cli.md is what scripts/cli_reference.py makes from the current ``--help``;
- no file sends readers to the design document outside the repository.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from wpbench.names import DEFAULT_EXECUTOR

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
DOCS = REPO / "docs"
README_MAX_CHARS = 10_000
OPENING_COMMANDS = (
    "make run    # set up (system packages + .venv), then `wpbench run --policy wp` on open-then-place (val split)\n"
    "make test   # set up, then run the test suite\n"
)
SLOW_MARKER = re.compile(r"#\s*slow\s*$")
NEEDS_MARKER = re.compile(r"#\s*needs:\s*\S.*$")
# Skipped commands are listed in the report; more than this many means the docs show too
# little that is checked.
MAX_SKIPPED_COMMANDS = 15
COMMAND_TIMEOUT_S = 300
# Built from parts so that this file does not match its own search.
OUTSIDE_DESIGN_DOC = "DESIGN" + ".md"

FENCE = re.compile(r"^```([\w-]*)\s*$")
LINK = re.compile(r"(?<!\!)\[[^\]]*\]\(([^)\s]+)\)")
CODE_SPAN = re.compile(r"`[^`]*`")


def doc_files() -> list[Path]:
    return [README, *sorted(DOCS.glob("*.md")), REPO / "results" / "experiments" / "README.md"]


@dataclass(frozen=True)
class Block:
    language: str
    lines: tuple[str, ...]
    start: int  # line number of the opening fence (1-based)


def blocks(text: str) -> list[Block]:
    """Fenced code blocks of a markdown text."""
    found, current, language, start = [], None, "", 0
    for number, line in enumerate(text.splitlines(), 1):
        match = FENCE.match(line.strip())
        if current is None and match:
            current, language, start = [], match.group(1), number
        elif current is not None and line.strip() == "```":
            found.append(Block(language, tuple(current), start))
            current = None
        elif current is not None:
            current.append(line)
    return found


def prose_lines(text: str) -> list[str]:
    """The lines of a markdown text outside fenced code blocks."""
    out, inside = [], False
    for line in text.splitlines():
        if FENCE.match(line.strip()):
            inside = not inside
            continue
        if not inside:
            out.append(line)
    return out


def github_anchor(heading: str) -> str:
    """The anchor GitHub gives a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = heading.strip().lower().replace("`", "")
    text = "".join(ch for ch in text if ch.isalnum() or ch in " -_")
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    result = set()
    for line in prose_lines(path.read_text()):
        match = re.match(r"^#{1,6}\s+(.*)$", line)
        if not match:
            continue
        anchor = github_anchor(match.group(1))
        count = seen.get(anchor, 0)
        result.add(anchor if count == 0 else f"{anchor}-{count}")
        seen[anchor] = count + 1
    return result


def test_every_relative_link_resolves() -> None:
    broken = []
    checked = 0
    for doc in doc_files():
        for line in prose_lines(doc.read_text()):
            for target in LINK.findall(CODE_SPAN.sub("", line)):
                if re.match(r"^[a-z]+:", target):
                    continue  # http(s), mailto
                checked += 1
                path_part, _, anchor = target.partition("#")
                resolved = (doc.parent / path_part).resolve() if path_part else doc
                where = f"{doc.relative_to(REPO)}: ({target})"
                if not resolved.exists():
                    broken.append(f"{where}: {path_part} does not exist")
                elif anchor and resolved.suffix == ".md" and anchor not in anchors(resolved):
                    broken.append(f"{where}: no heading with anchor #{anchor} in {resolved.relative_to(REPO)}")
    assert checked > 20, f"only {checked} links found; is the link pattern right?"
    assert not broken, "broken links:\n" + "\n".join(broken)


def test_anchor_rule_matches_github() -> None:
    assert github_anchor("The weighted SVD") == "the-weighted-svd"
    assert github_anchor("Environment (`wpbench.tasks`)") == "environment-wpbenchtasks"
    assert github_anchor("wpbench assets list") == "wpbench-assets-list"


def test_readme_is_a_front_page_opening_with_the_two_commands() -> None:
    text = README.read_text()
    assert len(text) <= README_MAX_CHARS, f"README.md has {len(text)} characters; keep it <= {README_MAX_CHARS} (move detail to docs/)"
    lines = text.splitlines(keepends=True)
    body = lines[1:] if lines[0].startswith("# ") else lines
    opening = "".join(body).lstrip("\n")
    assert opening.startswith("```bash\n" + OPENING_COMMANDS + "```\n"), "README.md must open with the make run / make test block"


@pytest.mark.parametrize("target", ["run", "test"])
def test_the_opening_make_targets_exist(target: str) -> None:
    # `make -n` prints the recipe without running it (running them is `make test` itself).
    done = subprocess.run(["make", "-n", target], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "scripts/setup.sh" in done.stdout


def test_readme_results_table_matches_the_summaries() -> None:
    """Each cell: the default executor's rate and interval, then the ideal executor's rate in brackets,
    from runs carried out by today's version of the executor."""
    from wpbench.evaluation.executor_version import older_executor_reason

    text = README.read_text()
    header = "| policy | open-door | place-in | open-then-place | episodes per task |"
    assert header in text, "README.md lost its results table"
    rows = text.split(header, 1)[1].split("\n\n", 1)[0].strip().splitlines()[1:]
    assert len(rows) >= 5
    runs = REPO / "results" / "runs"
    for row in rows:
        cells = [cell.strip() for cell in row.strip("|").split("|")]
        policy = cells[0].strip("`")
        counts = set()
        for task, cell in zip(("open-door", "place-in", "open-then-place"), cells[1:4]):
            default_run = runs / f"{policy}__{task}__val__procedural__camera__{DEFAULT_EXECUTOR}"
            assert older_executor_reason(default_run) is None, f"README results table quotes a stale run: {older_executor_reason(default_run)}"
            default = json.loads((default_run / "summary.json").read_text())
            ideal = json.loads((runs / f"{policy}__{task}__val__procedural__camera" / "summary.json").read_text())
            low, high = default["success_ci95"]
            expected = (f"{round(100 * default['success_rate'])}% [{round(100 * low)}, {round(100 * high)}]"
                        f" ({round(100 * ideal['success_rate'])}%)")
            assert cell == expected, f"README results table, {policy} on {task}: {cell!r}, summaries say {expected!r}"
            counts.add(str(default["episodes"]))
        assert cells[4] == "/".join(sorted(counts)), f"README results table, {policy}: episodes {cells[4]!r}, summaries {counts}"


def test_cli_reference_is_up_to_date() -> None:
    done = subprocess.run([sys.executable, str(REPO / "scripts" / "cli_reference.py"), "--check"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr + done.stdout


def test_nothing_points_to_the_design_document_outside_the_repository() -> None:
    listed = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"], cwd=REPO,
                            capture_output=True, text=True, check=True).stdout.splitlines()
    offenders = []
    for name in listed:
        path = REPO / name
        if not path.is_file() or path.suffix in (".pt", ".png", ".rrd", ".jsonl"):
            continue
        try:
            text = path.read_text()
        except (UnicodeDecodeError, OSError):
            continue
        if OUTSIDE_DESIGN_DOC in text or "../shared/" + "DESIGN" in text:
            offenders.append(name)
    assert not offenders, f"these files point to {OUTSIDE_DESIGN_DOC} outside the repository; point to docs/design.md: {offenders}"


# ------------------------------------------------------------------ the commands shown


@dataclass(frozen=True)
class Command:
    doc: str
    line: int
    text: str

    @property
    def skip_reason(self) -> str | None:
        if SLOW_MARKER.search(self.text):
            return "slow"
        needs = NEEDS_MARKER.search(self.text)
        return needs.group(0).lstrip("# ").strip() if needs else None


def commands_of(doc: Path) -> tuple[list[Command], dict[str, str]]:
    """The bash commands of ``doc`` (continuation lines joined) and its ``# file:`` python blocks."""
    text = doc.read_text()
    found, files = [], {}
    for index, block in enumerate(blocks(text)):
        if block.language == "python" and block.lines and block.lines[0].startswith("# file:"):
            files[block.lines[0].split(":", 1)[1].strip()] = "\n".join(block.lines[1:]) + "\n"
        if block.language != "bash":
            continue
        if doc == README and index == 0:
            continue  # the make run / make test block: checked by the tests above
        pending, first = "", 0
        for offset, line in enumerate(block.lines, 1):
            if not pending and (not line.strip() or line.strip().startswith("#")):
                continue
            first = first or block.start + offset
            if line.rstrip().endswith("\\"):
                pending += line.rstrip()[:-1] + " "
                continue
            found.append(Command(str(doc.relative_to(REPO)), first, pending + line.strip()))
            pending, first = "", 0
    return found, files


def all_commands() -> list[tuple[Command, dict[str, str]]]:
    out = []
    for doc in doc_files():
        commands, files = commands_of(doc)
        out.extend((command, files) for command in commands)
    return out


def test_commands_are_found_and_few_are_skipped() -> None:
    commands = [command for command, _ in all_commands()]
    skipped = [c for c in commands if c.skip_reason]
    assert len(commands) - len(skipped) >= 8, "the docs show too few commands that can be checked"
    assert len(skipped) <= MAX_SKIPPED_COMMANDS, (
        f"{len(skipped)} commands are skipped (limit {MAX_SKIPPED_COMMANDS}):\n"
        + "\n".join(f"{c.doc}:{c.line}: {c.text}" for c in skipped))


def _workspace(tmp_path: Path) -> Path:
    """A scratch folder that looks like the checkout to a command, without letting it write there."""
    work = tmp_path / "work"
    work.mkdir()
    for name in ("scripts", "policies", "tasks", "wpbench", "docs", "tests", "Makefile", "pyproject.toml"):
        (work / name).symlink_to(REPO / name)
    # Commands may write under results/ (the default output of `wpbench run`): give them a copy of
    # the published summaries, not the real folder.
    shutil.copytree(REPO / "results", work / "results",
                    ignore=shutil.ignore_patterns("*.jsonl", "*.pt", "*.png", "*.rrd"))
    return work


@pytest.mark.slow
def test_every_cheap_command_in_the_docs_runs(tmp_path: Path) -> None:
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
           "OMP_NUM_THREADS": "1"}
    work = _workspace(tmp_path)
    ran, skipped, failures = [], [], []
    for command, files in all_commands():
        if command.skip_reason:
            skipped.append(f"{command.doc}:{command.line}: {command.text}")
            continue
        for name, content in files.items():
            (work / name).write_text(content)
        done = subprocess.run(["bash", "-c", command.text], cwd=work, env=env, capture_output=True, text=True,
                              timeout=COMMAND_TIMEOUT_S)
        ran.append(command.text)
        if done.returncode != 0:
            failures.append(f"{command.doc}:{command.line}: `{command.text}` exited {done.returncode}:\n"
                            f"{(done.stderr or done.stdout).strip()[-2000:]}")
    print(f"ran {len(ran)} documented commands; skipped {len(skipped)}:\n" + "\n".join(skipped))
    assert ran, "no documented command was run"
    assert not failures, "\n\n".join(failures)
