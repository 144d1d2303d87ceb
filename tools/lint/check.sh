#!/usr/bin/env bash
# Style checks run by .ci/run before the build: every C++ file formatted as .clang-format says
# (Google style), and no function in core/, server/, client/ or tools/ over 80 lines unless a
# "long:" comment above it says why (tools/lint/function_length.py).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$root"
mapfile -t files < <(find core server client tools tests bench -type f \( -name '*.h' -o -name '*.cpp' \) | sort)
clang-format --dry-run -Werror "${files[@]}"
echo "clang-format: ${#files[@]} files formatted as .clang-format says"
python3 tools/lint/function_length.py --baseline tools/lint/function_length_baseline.txt core server client tools
