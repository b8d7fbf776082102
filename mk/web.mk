# web — the interactive demo in a web page: `charctl export RUN --web DIR [--serve]` (docs/web.md)
# web-deps: the npm packages pinned in web/package.json + web/package-lock.json (MuJoCo WebAssembly,
# onnxruntime-web, three.js, playwright-core), installed with `npm ci` (re-run only when either file changes).
# web-test-deps: Debian's chromium (and chromium-driver) for the browser test, with apt-get when root.
# `make test` depends on both; `make demo` also writes the site of the shipped 3-skill policy.
WEB_STAMP := web/node_modules/.charctl-npm-ci
WEB_DEMO_OUT := outputs/demo/web
CHROMIUM ?= /usr/bin/chromium

.PHONY: web-deps web-test-deps demo-web test-web

web-deps: $(WEB_STAMP) ## web: npm ci in web/ (the pinned MuJoCo wasm, onnxruntime-web, three.js, playwright-core)

$(WEB_STAMP): web/package.json web/package-lock.json
	@if command -v npm >/dev/null; then \
	  cd web && npm ci --ignore-scripts --no-audit --no-fund --loglevel=error && touch ../$(WEB_STAMP); \
	else echo "note: npm not found: install Node.js 18+ for the web demo (tests/test_web.py skips without it)"; fi

web-test-deps: web-deps ## web: Debian's chromium for the headless-browser test (apt-get, when root)
	@if [ -x "$(CHROMIUM)" ]; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	  echo "installing Debian's chromium for tests/test_web.py (apt-get)"; \
	  export DEBIAN_FRONTEND=noninteractive; \
	  (apt-get install -y -qq chromium chromium-driver >/dev/null 2>&1 \
	    || (apt-get update -qq >/dev/null 2>&1 && apt-get install -y -qq chromium chromium-driver >/dev/null 2>&1)) \
	  || echo "note: could not install chromium; tests/test_web.py's browser test will skip"; \
	else echo "note: install chromium (Debian: apt-get install chromium) for tests/test_web.py's browser test"; fi

test: web-deps web-test-deps

demo-web: install web-deps ## web: the shipped 3-skill policy as an interactive web page -> outputs/demo/web/ (serve it: python3 -m http.server -d outputs/demo/web)
	$(CHARCTL) export $(CGAIL_DEMO_POLICY) --web $(WEB_DEMO_OUT)

demo: demo-web

test-web: install web-deps web-test-deps ## web: only the web demo's tests (Node and headless Chromium; ~1 min)
	$(PY) -m pytest -q tests/test_web.py

test-slow: web-deps  # the documented `charctl export RUN --web DIR` commands run there (tests/test_doc_commands.py)
