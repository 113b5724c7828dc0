#!/usr/bin/env bash
# Regenerates the docs' tables that come from one definition in the code (tests/python/test_column_table.py
# fails when they are stale): docs/curve_columns.md from the column table (`dem info --columns`) and the
# key list in docs/contact_models.md from the sub-model registry (`dem info --contact-models`).
set -euo pipefail
cd "$(dirname "$0")/.."
DEM=${DEM_BIN:-build/dem}
{
  echo "# Curve columns"
  echo
  echo "Every column of a curve CSV, in file order: generated from the column table"
  echo "(\`column_table()\`, sim/src/measure/measure.cpp) by \`scripts/make_docs_tables.sh\`; \`dem info --columns\`"
  echo "prints the same (\`--json\` for programs; \`demtk.column_table()\` in Python). \"in\": every curve;"
  echo "\"rotations\": curves of a model with rotations (a tangential sub-model); \"path\": loading-path curves;"
  echo "\"path_sheared\": path curves with a shear stage. Definitions in detail: docs/definitions.md."
  echo
  "$DEM" info --columns
} > docs/curve_columns.md.part
mv docs/curve_columns.md.part docs/curve_columns.md
/usr/bin/python3 - "$DEM" <<'PY'
import subprocess, sys
doc = "docs/contact_models.md"
text = open(doc).read()
begin, end = "<!-- registry: begin (scripts/make_docs_tables.sh) -->", "<!-- registry: end -->"
listing = subprocess.run([sys.argv[1], "info", "--contact-models"], capture_output=True, text=True, check=True).stdout
block = begin + "\n```\n" + listing + "```\n" + end
a, b = text.index(begin), text.index(end) + len(end)
open(doc + ".part", "w").write(text[:a] + block + text[b:])
import os; os.replace(doc + ".part", doc)
PY
echo "make_docs_tables.sh: docs/curve_columns.md and docs/contact_models.md's key list are current"
