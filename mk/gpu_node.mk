# Offline GPU node (docs/gpu.md): a node with its own Python 3.12 + CUDA torch, no package registry, and
# transfers of at most 64 MiB each, the working tree included. Included by the Makefile.
# `make node-bundle` (here, with PyPI) resolves and downloads the wheels the node lacks, checks their
# closure against scripts/node_packages.txt, copies the clip files, and splits one tar.xz into
# .node/parts/ sized to the tree; it prints the device calls. On the node, every call runs
# `python3 scripts/node_run.py receive`, the last one also `python3 scripts/node_run.py run` (= `make node-run`).
NODE_CACHE ?= /tmp/charctl-node
NODE_WITHOUT ?=
NODE_BUDGET ?= 540

.PHONY: node-bundle node-plan node-run

node-bundle: install ## offline GPU node: wheels it lacks (closure checked for Python 3.12) + clip files -> .node/parts/; prints the device calls
	$(PY) scripts/node_bundle.py build --cache $(NODE_CACHE) $(if $(NODE_WITHOUT),--without $(NODE_WITHOUT))

node-plan: install ## offline GPU node: the device calls for the working tree as it is now (re-splits the parts when one no longer fits)
	$(PY) scripts/node_bundle.py plan --cache $(NODE_CACHE) $(if $(NODE_WITHOUT),--without $(NODE_WITHOUT))

node-run: ## ON THE NODE, once every part came: install into .node/venv, parity tests, bench, a time-boxed paper run -> $OUT/report.md
	python3 scripts/node_run.py run --budget $(NODE_BUDGET)
