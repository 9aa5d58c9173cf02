#!/usr/bin/env python3
"""Runs the commands quoted in README.md and docs/*.md and compares their output with the quoted
text, so that the documentation cannot drift from the program.

    python3 tests/check_docs.py STUDY [PAGE ...] [--timeout S] [--needs-only] [--show]

STUDY is the `study` binary to check (CI: ./target/release/study); PAGE defaults to README.md
and every docs/*.md. Python standard library only. Exit status 0 when every checked block
matches, 1 when one differs or fails, 2 on bad arguments or an unmarked output block.

The convention, for whoever writes the documentation
====================================================

Checked blocks. A fenced block whose info string is `console` is run. In it, a line starting
with `$ ` is a command (a command whose line ends with a backslash goes on over the next
lines); the lines after it, up to the next `$ ` line or the end of the block, are its expected
output: what a terminal shows, stdout and stderr together. A command that exits with a status
other than 0 shows it as its last output line, `[exit N]`. A command is a bash command line:
pipes (`| head -11`, `| grep verdict`) are fine, and the status is that of the pipeline's last
command.

    ```console
    $ study sim studies/sim_3hz_1p73g.toml | head -2
    study sim studies/sim_3hz_1p73g.toml
      excitation  sine 3 Hz, 1.73 g (0.0477 m), taper 1 s, 3 s run, window 4 cycles
    ```

Where the commands run. Every page gets a scratch folder that mirrors the repository root (a
symbolic link to each of its top-level entries but hidden ones and target/), and its blocks
run there in the order of the page, each command with a time limit (--timeout, 120 s). So a
command reads `studies/...`, `tests/...` or `docs/...` as in the repository root, a file it
writes with a relative name (`--out run.parquet`) lands in the scratch folder, not in the
repository, and a later block of the same page can use what an earlier one wrote. A path
starting with `/tmp/` in a command is the scratch folder's own `tmp/`. `study` is the binary
under test (its folder is put first on PATH). A block must not write into studies/, docs/ or
tests/ (they are the repository's own, through the links); when the repository is a git
checkout, the script fails if `git status --porcelain --ignored` changed while it ran.

Normalisation, applied to the real output before the comparison:
  - trailing white space on every line and trailing empty lines are dropped;
  - the scratch folder's `tmp/` prints as `/tmp/`;
  - the path of the binary under test prints as `/home/you/vshake/target/release/study`, and
    the scratch folder and the repository's absolute path as `/home/you/vshake` (the docs
    speak of a clone in /home/you/vshake).
Elisions, written in the quoted output for what varies legitimately from run to run or machine
to machine (timings, throughput, thread counts, the engine and backend, dates, absolute paths):
  - a line holding only `...` matches any number of lines, none included;
  - `...` inside a line matches any text within that line.
Nothing else is loosened: a number that is shown is compared to the character.

Blocks that need a rebuilt binary. `console needs=NAME` marks a block that needs the effect NAME
in the library (the tutorial "an effect the library does not have" adds one and rebuilds). It is
skipped, and said so, when `study params NAME` fails; with --needs-only, only such blocks run,
and a missing need is a failure (.ci/run does this after the tutorial's rebuild). Such a block
must not depend on an earlier block of its page.

Every other fenced block must be one of:
  - `toml`, `python`, `rust`, `matlab`, `csv`: a file or program, shown, not run here
    (docs/python.md's `python` blocks are run by python/tests/test_docs.py);
  - `sh` or `bash`: commands shown without their output; a line starting with `$ ` (a prompt
    and thus an output to follow) is refused there;
  - `text` directly after a `python` block (blank lines between): that cell's printed output,
    not compared here (docs/python.md);
  - `text` marked as not checked, by an HTML comment on the line just before the fence (blank
    lines allowed) that starts `<!-- illustrative:` and says why (a machine's benchmark figures,
    a fragment of an output that no bundled file produces).
A fence without an info string, or any other, stops the script before anything runs (exit 2),
so an output cannot be quoted unchecked by accident.

When a command's output goes through a pipe, send its stderr along (`2>&1 | sed ...`): a warning
written to stderr beside a pipe would land before or after the piped lines depending on timing.

Links. Every relative link of the pages (`[text](guide.md#anchor)`, `![figure](figures/x.svg)`)
must name a file that exists, and an anchor must be a heading of the page it names (GitHub's
rule: the heading in lower case, without punctuation, spaces as hyphens). A broken link fails
the check like a differing output.
"""
import argparse
import difflib
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHOWN_ROOT = "/home/you/vshake"
SHOWN_BIN = SHOWN_ROOT + "/target/release/study"
FILE_LANGS = {"toml", "python", "rust", "matlab", "csv"}
COMMAND_LANGS = {"sh", "bash"}
ELLIPSIS = "..."


class Block:
    def __init__(self, page, line, lang, args, body, marked, after_python):
        self.page, self.line, self.lang, self.args = page, line, lang, args
        self.body, self.marked, self.after_python = body, marked, after_python

    @property
    def where(self):
        return f"{self.page}:{self.line}"

    @property
    def needs(self):
        return [a.split("=", 1)[1] for a in self.args if a.startswith("needs=")]


def fenced_blocks(page):
    """The fenced blocks of a Markdown page: their line (1-based, the opening fence), info
    string, body lines, whether an `<!-- illustrative:` comment precedes them, and whether a
    `python` block comes just before."""
    lines = open(os.path.join(ROOT, page), encoding="utf-8").read().split("\n")
    blocks, i, last_lang, last_end = [], 0, None, -10
    while i < len(lines):
        m = re.match(r"^(\s*)(`{3,}|~{3,})\s*(.*)$", lines[i])
        if not m:
            i += 1
            continue
        fence, info = m.group(2), m.group(3).split()
        if m.group(1):
            info = ["(indented)"]
        start, i = i, i + 1
        body = []
        while i < len(lines) and not re.match(r"^\s*" + re.escape(fence[0]) + "{%d,}\\s*$" % len(fence), lines[i]):
            body.append(lines[i])
            i += 1
        k = start - 1
        while k >= 0 and not lines[k].strip():
            k -= 1
        marked = k >= 0 and lines[k].strip().startswith("<!-- illustrative:")
        between = lines[last_end + 1:start] if last_end >= 0 else ["x"]
        after_python = last_lang == "python" and all(not s.strip() for s in between)
        lang = info[0] if info else ""
        blocks.append(Block(page, start + 1, lang, info[1:], body, marked, after_python))
        last_lang, last_end = lang, i
        i += 1
    return blocks


def slug(heading):
    text = "".join(c for c in heading.strip().lower() if c.isalnum() or c in " -_")
    return text.replace(" ", "-")


def anchors(page):
    """The anchors of a page's headings, outside fenced blocks, as GitHub makes them."""
    out, seen, fence = set(), {}, None
    for line in open(os.path.join(ROOT, page), encoding="utf-8"):
        m = re.match(r"^(`{3,}|~{3,})", line)
        if m and fence is None:
            fence = m.group(1)[0]
        elif m and line.strip()[0] == fence:
            fence = None
        elif fence is None and re.match(r"^#{1,6} ", line):
            a = slug(line.lstrip("#"))
            n = seen.get(a, 0)
            seen[a] = n + 1
            out.add(a if n == 0 else f"{a}-{n}")
    return out


def broken_links(page):
    """'page:line: why' for every relative link of a page that names no file or no heading."""
    out, fence = [], None
    for number, line in enumerate(open(os.path.join(ROOT, page), encoding="utf-8"), 1):
        m = re.match(r"^(`{3,}|~{3,})", line)
        if m and fence is None:
            fence = m.group(1)[0]
            continue
        if m and line.strip()[0] == fence:
            fence = None
            continue
        if fence is not None:
            continue
        for target in re.findall(r"\]\(([^)\s]+)\)", re.sub(r"`[^`]*`", "", line)):
            if re.match(r"^[a-z]+:", target):
                continue
            path, _, anchor = target.partition("#")
            name = os.path.normpath(os.path.join(os.path.dirname(page), path)) if path else page
            if not os.path.exists(os.path.join(ROOT, name)):
                out.append(f"{page}:{number}: link to {target}: there is no {name}")
            elif anchor and name.endswith(".md") and anchor not in anchors(name):
                out.append(f"{page}:{number}: link to {target}: {name} has no heading #{anchor}")
    return out


def classify(block):
    """'check', 'skip-file', 'skip-commands', 'unchecked' or an error message."""
    if block.lang == "console":
        if not block.body or not block.body[0].startswith("$ "):
            return "a console block must start with a `$ ` command line"
        return "check"
    if block.lang in FILE_LANGS:
        return "skip-file"
    if block.lang in COMMAND_LANGS:
        if any(l.startswith("$ ") for l in block.body):
            return f"a {block.lang} block holds a `$ ` prompt: write it as a console block (checked)"
        return "skip-commands"
    if block.lang == "text" and (block.marked or block.after_python):
        return "unchecked"
    if block.lang == "(indented)":
        return "an indented fence: write fenced blocks at the start of the line, outside lists"
    if block.lang == "text":
        return "a text block that is neither checked (console) nor marked `<!-- illustrative: why -->`"
    return f"a fence with info string {block.lang!r}: use console (checked), text (marked illustrative) or one of {sorted(FILE_LANGS | COMMAND_LANGS)}"


def commands(block):
    """[(line, command, expected output lines)] of a console block."""
    out, i, body = [], 0, block.body
    while i < len(body):
        line = block.line + 1 + i
        cmd = body[i][2:]
        while cmd.endswith("\\") and i + 1 < len(body):
            i += 1
            cmd = cmd + "\n" + body[i]
        i += 1
        expected = []
        while i < len(body) and not body[i].startswith("$ "):
            expected.append(body[i])
            i += 1
        out.append((line, cmd, trim(expected)))
    return out


def trim(lines):
    lines = [l.rstrip() for l in lines]
    while lines and not lines[-1]:
        lines.pop()
    return lines


def line_pattern(text):
    if text.strip() == ELLIPSIS:
        return None
    return re.compile(".*?".join(re.escape(p) for p in text.split(ELLIPSIS)) + r"\Z", re.S)


def align(expected, actual):
    """The cheapest alignment of the expected lines (with elisions) to the actual ones: (cost,
    the actual output rendered line by line as the expected one wherever it matched). Cost 0 is
    a match."""
    pats = [line_pattern(e) for e in expected]
    ne, na = len(expected), len(actual)
    inf = float("inf")
    cost = [[inf] * (na + 1) for _ in range(ne + 1)]
    move = [[None] * (na + 1) for _ in range(ne + 1)]
    for i in range(ne, -1, -1):
        for j in range(na, -1, -1):
            if i == ne:
                cost[i][j], move[i][j] = na - j, "extra"
                continue
            options = []
            if pats[i] is None:
                options.append((cost[i + 1][j], "leave"))
                if j < na:
                    options.append((cost[i][j + 1], "absorb"))
            else:
                if j < na and pats[i].match(actual[j]):
                    options.append((cost[i + 1][j + 1], "match"))
                options.append((1 + cost[i + 1][j], "missing"))
                if j < na:
                    options.append((1 + cost[i][j + 1], "extra"))
            cost[i][j], move[i][j] = min(options, key=lambda o: o[0])
    rendered, i, j = [], 0, 0
    while i < ne or j < na:
        m = move[i][j]
        if m == "extra":
            rendered.append(actual[j])
            j += 1
        elif m == "match":
            rendered.append(expected[i])
            i, j = i + 1, j + 1
        elif m == "leave":
            rendered.append(expected[i])
            i += 1
        elif m == "absorb":
            j += 1
        else:  # missing
            i += 1
    return cost[0][0], rendered


def mirror(scratch):
    for name in sorted(os.listdir(ROOT)):
        if name.startswith(".") or name == "target":
            continue
        os.symlink(os.path.join(ROOT, name), os.path.join(scratch, name))
    os.mkdir(os.path.join(scratch, "tmp"))


def normalise(text, scratch, binary):
    pairs = [(os.path.realpath(binary), SHOWN_BIN), (binary, SHOWN_BIN)]
    for s in {scratch, os.path.realpath(scratch)}:
        pairs += [(os.path.join(s, "tmp"), "/tmp"), (s, SHOWN_ROOT)]
    pairs += [(os.path.realpath(ROOT), SHOWN_ROOT), (ROOT, SHOWN_ROOT)]
    for path, shown in sorted(pairs, key=lambda p: -len(p[0])):
        text = text.replace(path, shown)
    return trim(text.replace("\r\n", "\n").split("\n"))


def run(cmd, scratch, env, timeout):
    cmd = re.sub(r"(?<![\w./-])/tmp/", os.path.join(scratch, "tmp") + "/", cmd)
    try:
        p = subprocess.run(["bash", "-c", cmd], cwd=scratch, env=env, stdin=subprocess.DEVNULL,
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=timeout)
    except subprocess.TimeoutExpired as e:
        return None, (e.stdout or b"").decode("utf-8", "replace")
    out = p.stdout.decode("utf-8", "replace")
    if p.returncode != 0:
        out = (out.rstrip("\n") + "\n" if out.strip() else "") + f"[exit {p.returncode}]\n"
    return p.returncode, out


def git_state():
    if not os.path.isdir(os.path.join(ROOT, ".git")) and not os.path.isfile(os.path.join(ROOT, ".git")):
        return None
    try:
        return subprocess.run(["git", "-C", ROOT, "status", "--porcelain", "--ignored"],
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return None


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("study", help="the study binary to check")
    ap.add_argument("pages", nargs="*", help="Markdown pages, relative to the repository root "
                    "(default: README.md and docs/*.md)")
    ap.add_argument("--timeout", type=float, default=120.0, help="seconds per command (120)")
    ap.add_argument("--needs-only", action="store_true",
                    help="run only the blocks marked needs=NAME; a missing need fails")
    ap.add_argument("--show", action="store_true",
                    help="print every command's real output (normalised), to update a page")
    a = ap.parse_args()
    binary = os.path.abspath(a.study)
    if not (os.path.isfile(binary) and os.access(binary, os.X_OK)):
        sys.exit(f"check_docs: {a.study} is not an executable file")
    pages = a.pages or ["README.md"] + sorted(
        "docs/" + f for f in os.listdir(os.path.join(ROOT, "docs")) if f.endswith(".md"))

    plan, problems = [], []
    for page in pages:
        for b in fenced_blocks(page):
            kind = classify(b)
            if kind not in ("check", "skip-file", "skip-commands", "unchecked"):
                problems.append(f"{b.where}: {kind}")
            plan.append((b, kind))
    if problems:
        print("check_docs: blocks that break the convention (see tests/check_docs.py):")
        print("\n".join("  " + p for p in problems))
        sys.exit(2)

    bindir = tempfile.mkdtemp(prefix="check_docs_bin_")
    os.symlink(binary, os.path.join(bindir, "study"))
    env = dict(os.environ, PATH=bindir + os.pathsep + os.environ.get("PATH", ""), TZ="UTC")
    have = {}

    def has(effect):
        if effect not in have:
            have[effect] = subprocess.run([binary, "params", effect], stdout=subprocess.DEVNULL,
                                          stderr=subprocess.DEVNULL).returncode == 0
        return have[effect]

    links = [b for page in pages for b in broken_links(page)]
    for b in links:
        print(f"FAIL {b}")

    before = git_state()
    started = time.time()
    checked = ncommands = 0
    failed, skipped, unchecked = [], [], []
    scratches = {}
    for b, kind in plan:
        if kind == "unchecked":
            unchecked.append(b.where + (" (a python cell's output)" if b.after_python else " (illustrative)"))
        if kind != "check":
            continue
        missing = [n for n in b.needs if not has(n)]
        if a.needs_only and not b.needs:
            continue
        if missing and not a.needs_only:
            skipped.append(f"{b.where} (needs {', '.join(missing)}, which this study lacks)")
            print(f"skip {b.where}: needs {', '.join(missing)}")
            continue
        if missing:
            failed.append(b.where)
            print(f"FAIL {b.where}: needs {', '.join(missing)}, which {a.study} lacks")
            continue
        if b.page not in scratches:
            scratches[b.page] = tempfile.mkdtemp(prefix="check_docs_")
            mirror(scratches[b.page])
        scratch = scratches[b.page]
        t0, ok = time.time(), True
        for line, cmd, expected in commands(b):
            ncommands += 1
            t1 = time.time()
            status, out = run(cmd, scratch, env, a.timeout)
            actual = normalise(out, scratch, binary)
            if a.show:
                print(f"---- {b.page}:{line}: $ {cmd}")
                print("\n".join(actual))
            if status is None:
                ok = False
                print(f"FAIL {b.page}:{line}: `{cmd}` ran over {a.timeout:.0f} s; its output so far:")
                print("\n".join("  " + l for l in actual[-20:]))
                break
            cost, rendered = align(expected, actual)
            if cost:
                ok = False
                print(f"FAIL {b.page}:{line}: the output of `{cmd}` ({time.time() - t1:.1f} s) differs from the page:")
                sys.stdout.writelines(l + "\n" for l in difflib.unified_diff(
                    expected, rendered, f"{b.page}:{line} (the page)", f"{b.page}:{line} (the real output)", lineterm=""))
        checked += 1
        n = len(commands(b))
        if ok:
            print(f"ok   {b.where}: {n} command{'s' if n > 1 else ''}, {time.time() - t0:.1f} s")
        else:
            failed.append(b.where)
        sys.stdout.flush()
    for s in list(scratches.values()) + [bindir]:
        shutil.rmtree(s, ignore_errors=True)

    after = git_state()
    if before is not None and after != before:
        failed.append("the repository")
        print("FAIL the documentation's commands changed the repository (git status --porcelain --ignored):")
        print("".join(difflib.unified_diff(before.decode().splitlines(True), after.decode().splitlines(True), "before", "after")))

    if links:
        failed.append(f"{len(links)} broken link{'s' if len(links) > 1 else ''}")
    print()
    print(f"check_docs: {checked} block{'s' if checked != 1 else ''} ({ncommands} commands) checked in {len(pages)} pages, "
          f"{time.time() - started:.0f} s; {len(failed)} failed, {len(skipped)} skipped, "
          f"{len(unchecked)} output blocks not checked by design")
    for s in skipped:
        print(f"  skipped: {s}")
    for u in unchecked:
        print(f"  not checked: {u}")
    if failed:
        print("  failed: " + ", ".join(failed))
        sys.exit(1)


if __name__ == "__main__":
    main()
