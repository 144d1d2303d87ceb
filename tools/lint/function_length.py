#!/usr/bin/env python3
"""Lists C++ functions longer than a limit (default 80 lines) in the given folders.

A function may be longer when the comment block right above it says why, with a line containing
"long:" (for example "// long: one table of knobs, read top to bottom"). Exit status 1 when a
function is over the limit without one, so CI keeps functions a reader can hold in mind.

The parser is a brace counter, not a compiler: it skips comments, strings and character
literals, treats namespace, class, struct, enum and extern blocks as scopes rather than bodies,
and counts a function from its opening brace's line to its closing brace's line.
"""
import argparse
import os
import re
import sys

SCOPE = re.compile(r"\b(namespace|class|struct|enum|union|extern\s+\"C\")\b[^;(]*$")


def strip(text):
    """The text with comments, strings and char literals blanked (newlines kept)."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif text.startswith('R"', i):
            m = re.match(r'R"([^(]*)\(', text[i:])
            end = text.find(")" + (m.group(1) if m else "") + '"', i)
            j = n if end < 0 else end + len(m.group(1) if m else "") + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c in "\"'":
            j = i + 1
            while j < n and text[j] != c:
                j += 2 if text[j] == "\\" else 1
            out.append(re.sub(r"[^\n]", " ", text[i:j + 1]))
            i = j + 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def functions(path):
    """(name, first line, last line) of each function body outside other bodies."""
    raw = open(path, encoding="utf-8", errors="replace").read()
    text = strip(raw)
    stack = []  # per open brace: "scope", "body" or "inner"
    header_start = 0
    found = []
    line = 1
    for i, c in enumerate(text):
        if c == "\n":
            line += 1
        elif c in ";}" and (not stack or stack[-1] == "scope"):
            if c == "}":
                stack.pop() if stack else None
            header_start = i + 1
        elif c == "{":
            header = text[header_start:i]
            if stack and stack[-1] != "scope":
                stack.append("inner")
            elif SCOPE.search(header.strip().split("\n")[-1] if header.strip() else "") or \
                    re.search(r"\b(namespace|class|struct|enum|union)\b", header) and "(" not in header:
                stack.append("scope")
                header_start = i + 1
            elif "(" in header and "=" not in header.split("(")[0]:
                name = re.findall(r"([~\w:]+)\s*\(", header)
                stack.append(("body", name[0] if name else "?", line))
            else:
                stack.append("inner")
        elif c == "}":
            top = stack.pop() if stack else None
            if isinstance(top, tuple):
                found.append((top[1], top[2], line))
                header_start = i + 1
    return raw.split("\n"), found


def justified(lines, first):
    """True when the comment block above the function's signature has a "long:" line."""
    j = first - 2
    while j >= 0 and lines[j].strip() and not lines[j].strip().startswith("//"):
        j -= 1  # the signature's own lines
    while j >= 0 and lines[j].strip().startswith("//"):
        if "long:" in lines[j]:
            return True
        j -= 1
    return False


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("folders", nargs="+")
    ap.add_argument("--max", type=int, default=80)
    ap.add_argument("--baseline", help="file of 'path function' lines still to be split: they are "
                    "listed but do not fail (a ratchet: new long functions do)")
    args = ap.parse_args()
    known = set()
    if args.baseline:
        for entry in open(args.baseline, encoding="utf-8"):
            entry = entry.split("#")[0].strip()
            if entry:
                known.add(tuple(entry.split()))
    bad = 0
    for folder in args.folders:
        for root, _, files in os.walk(folder):
            for f in sorted(files):
                if not f.endswith((".cpp", ".h", ".cc")):
                    continue
                path = os.path.join(root, f)
                lines, found = functions(path)
                for name, first, last in found:
                    n = last - first + 1
                    if n > args.max and not justified(lines, first):
                        listed = (path, name) in known
                        print("%s:%d: %s is %d lines (over %d, and no 'long:' comment says why)%s"
                              % (path, first, name, n, args.max,
                                 " [baseline: still to split]" if listed else ""))
                        bad += 0 if listed else 1
    print("function_length: %d function(s) over %d lines without a reason" % (bad, args.max))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
