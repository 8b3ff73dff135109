#!/usr/bin/env python3
"""Checks that the libraries throw only the toolkit's own exceptions (libtsah/include/tsah/base/error.hpp).

Every throw in libanim/, libtsah/, cuda_kernels/ and python/src/ must say whose mistake it is:
tsah::ConfigError, tsah::DataError / tsah::FileError or tsah::Failure (or a class derived from one).
A bare tsah::Error, the standard library's std::invalid_argument / std::runtime_error /
std::out_of_range and pybind11's py::value_error / py::type_error say nothing of that, so each is
reported as FILE:LINE: text. Comments and string literals are not searched. Rethrowing (throw;,
std::rethrow_exception) is fine.

usage: scripts/check-throws.py   (exit 0: clean; 1: one line per forbidden throw)
"""
import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FOLDERS = ["libanim", "libtsah", "cuda_kernels", "python/src"]
EXTENSIONS = (".cpp", ".hpp", ".h", ".cc", ".cu", ".cuh")

FORBIDDEN = re.compile(
    r"\bthrow\s+(?:"
    r"(?:::)?(?:tsah::)?Error\s*[({]"  # a bare tsah::Error (not ConfigError, FileError, ...)
    r"|(?:::)?std::(?:invalid_argument|runtime_error|out_of_range)\b"
    r"|(?:pybind11|py)::(?:value_error|type_error)\b"
    r")")


def code_only(text):
    """text with comments and the contents of string and character literals blanked out (newlines
    kept, so line numbers stay)."""
    out = []
    i, n = 0, len(text)
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
            out.append("".join(ch if ch == "\n" else " " for ch in text[i:j]))
            i = j
        elif text.startswith('R"', i) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            m = re.match(r'R"([^(\s]*)\(', text[i:])
            if not m:
                out.append(c)
                i += 1
                continue
            end = text.find(")" + m.group(1) + '"', i + m.end())
            j = n if end < 0 else end + len(m.group(1)) + 2
            out.append("".join(ch if ch == "\n" else " " for ch in text[i:j]))
            i = j
        elif c == '"' or (c == "'" and not (i > 0 and text[i - 1].isalnum())):  # not a digit separator
            j = i + 1
            while j < n and text[j] != c and text[j] != "\n":
                j += 2 if text[j] == "\\" else 1
            j = min(j + 1, n)
            out.append(c + " " * (j - i - 2) + c if j - i >= 2 else text[i:j])
            i = j
        else:
            out.append(c)
            i += 1
    return "".join(out)


def check():
    hits = []
    files = 0
    for folder in FOLDERS:
        for dirpath, dirnames, filenames in os.walk(os.path.join(ROOT, folder)):
            dirnames.sort()
            for name in sorted(filenames):
                if not name.endswith(EXTENSIONS):
                    continue
                path = os.path.join(dirpath, name)
                rel = os.path.relpath(path, ROOT)
                files += 1
                text = open(path, encoding="utf-8").read()
                code = code_only(text)
                lines = text.split("\n")
                for m in FORBIDDEN.finditer(code):
                    line = code.count("\n", 0, m.start()) + 1
                    hits.append(f"{rel}:{line}: {lines[line - 1].strip()}")
    return hits, files


def main():
    hits, files = check()
    for h in hits:
        print(h)
    if hits:
        print(f"check-throws: {len(hits)} throw(s) of a bare tsah::Error or a standard/pybind11 exception; throw "
              "tsah::ConfigError, DataError, FileError or Failure (libtsah/include/tsah/base/error.hpp)",
              file=sys.stderr)
        return 1
    print(f"check-throws: {files} files in {', '.join(FOLDERS)}, every throw says whose mistake it is")
    return 0


if __name__ == "__main__":
    sys.exit(main())
