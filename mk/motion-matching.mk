# motion-matching reproduction targets (included by the Makefile).
MM_OUT := outputs/repro/motion-matching

.PHONY: repro-motion-matching bench-motion-matching

repro-motion-matching: install ## motion-matching: Table 1 sweep (19 cases x 3 paths), star export (best case), bench -> outputs/repro/motion-matching/report.md
	$(CHARCTL) eval motion-matching --sweep -o $(MM_OUT)
	$(CHARCTL) export motion-matching path=star case=best output_root=$(MM_OUT) --bvh $(MM_OUT)/star_best.bvh --video $(MM_OUT)/star_best.mp4
	$(PY) scripts/bench_mm.py --json $(MM_OUT)/bench.json
	$(PY) -m charctl.experiments.motion_matching.report $(MM_OUT)
	@echo "report: $(MM_OUT)/report.md"

bench-motion-matching: install ## motion-matching: query latency (brute / kd-tree / bounding boxes, real and 50k frames) and real-time factor
	$(PY) scripts/bench_mm.py
