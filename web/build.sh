#!/usr/bin/env bash
# Build the page into riderlive/web/static: the JS bundle (three.js + our sources,
# esbuild) and skeletons.json (from riderlive.skeleton). Run from anywhere:
#   web/build.sh            (needs node >= 18; `npm ci` here on first use)
set -euo pipefail
cd "$(dirname "$0")"
[ -d node_modules ] || npm ci --no-audit --no-fund
PY="${PYTHON:-../.venv/bin/python}"
[ -x "$PY" ] || PY=python3
PYTHONPATH=.. "$PY" -c 'import json; from riderlive.skeleton import hello_skeletons; print(json.dumps(hello_skeletons(), indent=1, allow_nan=False))' > ../riderlive/web/static/skeletons.json
npx esbuild src/main.js --bundle --minify --format=esm --target=es2020 --legal-comments=linked \
    --outfile=../riderlive/web/static/app.js
cp src/index.html src/style.css ../riderlive/web/static/
ls -l ../riderlive/web/static
