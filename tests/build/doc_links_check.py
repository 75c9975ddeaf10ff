#!/usr/bin/python3
"""The documentation's links and set-up lines, checked without a network.

    doc_links_check.py check SOURCE_DIR     every Markdown file of the tree
    doc_links_check.py selftest             plants broken links in a temporary tree

`check` fails, one line per finding, on:
  * a relative link ([text](path), [text](path#anchor), [label]: path) whose file or folder
    does not exist in the repository, or that leaves the repository (a fresh clone has
    nothing beside it);
  * an anchor (#heading) that no heading of the target file makes, with GitHub's rule for
    heading ids;
  * a top-level README.md whose set-up lines are not the commands that
    deploy/fresh-machine-check.sh reads from it (the first indented line starting
    "apt-get update", "git clone" with "<repository URL>", exactly "deploy/main.sh" and
    "deploy/test.sh") or whose test command is not what .ci/run runs.
Links with a scheme (https:, mailto:) are not followed. Code spans and fenced code blocks
are not read for links.
"""

import os
import re
import sys
import tempfile
import unicodedata

SKIPPED_DIRS = {".git", "node_modules", "__pycache__"}
LINK = re.compile(r"!?\[(?:[^\]\\]|\\.)*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
REFERENCE = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+.*)?$")
HEADING = re.compile(r"^\s{0,3}(#{1,6})\s+(.*?)\s*#*\s*$")
SCHEME = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")
SETUP_LINES = ("apt-get update", "git clone", "deploy/main.sh", "deploy/test.sh")


def markdown_files(root):
    """The tree's Markdown files, without the build trees (build/, build-asan/, ...) at its top."""
    for directory, subdirs, files in os.walk(root):
        at_top = os.path.samefile(directory, root)
        subdirs[:] = sorted(d for d in subdirs
                            if d not in SKIPPED_DIRS and not (at_top and d.startswith("build")))
        for name in sorted(files):
            if name.endswith(".md"):
                yield os.path.join(directory, name)


def prose_lines(text, blank_code_spans=True):
    """(line number, line) outside fenced code blocks, with code spans blanked unless asked
    to keep them (headings keep theirs: they are part of the heading's id)."""
    fence = None
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.lstrip()
        marker = re.match(r"(`{3,}|~{3,})", stripped)
        if fence is None and marker:
            fence = marker.group(1)[0] * len(marker.group(1))
            continue
        if fence is not None:
            if stripped.startswith(fence):
                fence = None
            continue
        yield number, re.sub(r"`+[^`]*`+", "``", line) if blank_code_spans else line


def slug(heading):
    """GitHub's id for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"`([^`]*)`", r"\1", heading)
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text)
    text = text.strip().lower()
    kept = []
    for ch in text:
        category = unicodedata.category(ch)
        if ch in "-_ " or category[0] in "LN" or category == "Mn":
            kept.append(ch)
    return "".join(kept).replace(" ", "-")


def anchors(path):
    ids, seen = set(), {}
    with open(path, encoding="utf-8") as f:
        for _, line in prose_lines(f.read(), blank_code_spans=False):
            match = HEADING.match(line)
            if not match:
                continue
            base = slug(match.group(2))
            count = seen.get(base, 0)
            seen[base] = count + 1
            ids.add(base if count == 0 else f"{base}-{count}")
    return ids


def link_targets(text):
    for number, line in prose_lines(text):
        for match in LINK.finditer(line):
            yield number, match.group(1)
        match = REFERENCE.match(line)
        if match:
            yield number, match.group(1)


def check_links(root, path):
    root = os.path.realpath(root)
    with open(path, encoding="utf-8") as f:
        text = f.read()
    shown = os.path.relpath(path, root)
    for number, target in link_targets(text):
        if SCHEME.match(target):
            continue
        file_part, _, anchor = target.partition("#")
        if file_part:
            resolved = os.path.realpath(os.path.join(os.path.dirname(path), file_part))
            if not (resolved == root or resolved.startswith(root + os.sep)):
                yield f"{shown}:{number}: {target}: outside the repository"
                continue
            if not os.path.exists(resolved):
                yield f"{shown}:{number}: {target}: no such file or folder"
                continue
        else:
            resolved = path
        if anchor and resolved.endswith(".md") and os.path.isfile(resolved):
            if anchor not in anchors(resolved):
                yield f"{shown}:{number}: {target}: no heading #{anchor} in {os.path.relpath(resolved, root)}"


def readme_line(text, prefix):
    """The line deploy/fresh-machine-check.sh takes: the first one indented by four spaces
    that starts with `prefix`, without the indent and a trailing comment."""
    for line in text.splitlines():
        if line.startswith("    " + prefix):
            return re.sub(r" +#.*$", "", line[4:])
    return None


def check_setup(root):
    readme = os.path.join(root, "README.md")
    with open(readme, encoding="utf-8") as f:
        text = f.read()
    lines = {prefix: readme_line(text, prefix) for prefix in SETUP_LINES}
    for prefix, line in lines.items():
        if line is None:
            yield f"README.md: no set-up line starting '{prefix}' (deploy/fresh-machine-check.sh runs it)"
    if lines["git clone"] is not None and "<repository URL>" not in lines["git clone"]:
        yield "README.md: the clone line has no <repository URL>"
    for command in ("deploy/main.sh", "deploy/test.sh"):
        if lines[command] not in (None, command):
            yield f"README.md: the set-up line is '{lines[command]}', expected exactly '{command}'"
        if not os.access(os.path.join(root, command), os.X_OK):
            yield f"README.md: {command} is not an executable file"
    ci = os.path.join(root, ".ci", "run")
    if os.path.exists(ci):
        with open(ci, encoding="utf-8") as f:
            runs = [l.strip() for l in f if l.strip() and not l.lstrip().startswith("#")]
        if not any(re.fullmatch(r"(bash )?deploy/test\.sh", l) for l in runs):
            yield ".ci/run: does not run deploy/test.sh, the README's test command"


def check(root):
    findings = []
    count = 0
    for path in markdown_files(root):
        count += 1
        findings.extend(check_links(root, path))
    if os.path.exists(os.path.join(root, "deploy", "fresh-machine-check.sh")):
        findings.extend(check_setup(root))
    for finding in findings:
        print(finding)
    print(f"doc_links_check: {count} Markdown files, {len(findings)} findings")
    return 1 if findings or count == 0 else 0


def selftest():
    """Each kind of broken link must be found, and a clean tree must pass."""
    with tempfile.TemporaryDirectory() as tmp:
        def write(name, text):
            path = os.path.join(tmp, name)
            os.makedirs(os.path.dirname(path), exist_ok=True)
            with open(path, "w", encoding="utf-8") as f:
                f.write(text)
        write("a/README.md", "# A design\n\n## Measured (`x`)\n\nSee [b](../b/README.md#the-b-part) and [top](../README.md).\n")
        write("b/README.md", "# B\n\n## The B part\n\n```\n[not a link](nowhere.md)\n```\n`[code](nowhere.md)`\n")
        write("README.md", "# Top\n\n[a](a/README.md#measured-x), [self](#top)\n")
        if check(tmp) != 0:
            print("selftest: a tree without broken links failed")
            return 1
        broken = {
            "missing file": "[x](a/MISSING.md)",
            "missing anchor": "[x](a/README.md#no-such-heading)",
            "missing own anchor": "[x](#nowhere)",
            "outside the repository": "[x](../../elsewhere.md)",
            "reference definition": "[label]: b/missing.md",
        }
        for name, link in broken.items():
            write("README.md", f"# Top\n\n{link}\n")
            if check(tmp) == 0:
                print(f"selftest: the check missed a {name}: {link}")
                return 1
        write("README.md", "# Top\n\n    apt-get update && apt-get install -y git\n"
              "    git clone <repository URL> x && cd x\n\n    deploy/main.sh\n\n    deploy/test.sh\n")
        write(".ci/run", "#!/bin/sh\n# CI\nbash deploy/test.sh\n")
        for script in ("deploy/fresh-machine-check.sh", "deploy/main.sh", "deploy/test.sh"):
            write(script, "#!/bin/sh\n")
            os.chmod(os.path.join(tmp, script), 0o755)
        if check(tmp) != 0:
            print("selftest: a README with the set-up lines failed")
            return 1
        broken_setup = {
            "test command with an argument": ("README.md", "# Top\n\n    apt-get update\n    git clone <repository URL>\n"
                                              "    deploy/main.sh\n    deploy/test.sh --quick\n"),
            "missing clone line": ("README.md", "# Top\n\n    apt-get update\n    deploy/main.sh\n    deploy/test.sh\n"),
            "CI running something else": (".ci/run", "#!/bin/sh\nbash deploy/other.sh\n"),
        }
        for name, (file, text) in broken_setup.items():
            write("README.md", "# Top\n\n    apt-get update\n    git clone <repository URL>\n"
                  "    deploy/main.sh\n    deploy/test.sh\n")
            write(".ci/run", "#!/bin/sh\nbash deploy/test.sh\n")
            write(file, text)
            if check(tmp) == 0:
                print(f"selftest: the check missed a {name}")
                return 1
        print("selftest: every planted broken link and set-up line was found")
        return 0


def main(argv):
    if len(argv) == 3 and argv[1] == "check":
        return check(argv[2])
    if len(argv) == 2 and argv[1] == "selftest":
        return selftest()
    print(__doc__.strip().splitlines()[2], file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv))
