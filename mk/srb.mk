# srb — single rigid body + QP tracker + PPO (docs/srb.md)
SRB_OUT := outputs/repro/srb
SRB_BASELINE ?= auto

.PHONY: repro-srb bench-srb

repro-srb: install ## srb: train scale=small, push study vs the full-body AMP walk baseline (SRB_BASELINE=cgail run|auto) -> outputs/repro/srb/report.md
	$(CHARCTL) train srb scale=small output_root=$(SRB_OUT)/runs
	$(CHARCTL) eval $$(ls -d $(SRB_OUT)/runs/srb/*/ | tail -1) --push -o $(SRB_OUT) push.baseline_run=$(SRB_BASELINE) output_root=outputs
	$(CHARCTL) export $$(ls -d $(SRB_OUT)/runs/srb/*/ | tail -1) --video $(SRB_OUT)/srb_walk_push.mp4 --seconds 6
	@echo "report: $(SRB_OUT)/report.md"

bench-srb: install ## srb: QP solves/s, rollout and training samples/s in one run (vs the paper's rate)
	mkdir -p $(SRB_OUT) && $(PY) scripts/bench_srb.py --json $(SRB_OUT)/bench.json
