# hopper-ga (docs/hopper-ga.md): reproduction of Kang (1999) Fig 5.1-5.5 and 5.7, the limp test (Fig 3.13)
# and the COM path (Fig 3.14). Runs go to outputs/repro/hopper-ga/runs/, the report to
# outputs/repro/hopper-ga/report.md. HOPPER_GA_SCALE=small for a quicker pass.
HOPPER_GA_OUT ?= outputs/repro/hopper-ga
HOPPER_GA_SCALE ?= paper
HOPPER_GA_RUNTIME ?= local

.PHONY: repro-hopper-ga bench-hopper-ga

repro-hopper-ga: install ## hopper-ga: 2/5/7 m/s (beta 0), 10 m/s (beta 0.2, 0.7), 5 m/s beta 0.5 curve -> report.md
	rm -rf $(HOPPER_GA_OUT)
	$(CHARCTL) train hopper-ga -m speed=2,5,7 beta=0 scale=$(HOPPER_GA_SCALE) runtime.kind=$(HOPPER_GA_RUNTIME) output_root=$(HOPPER_GA_OUT)/runs $(LAUNCH)
	$(CHARCTL) train hopper-ga -m speed=10 beta=0.2,0.7 scale=$(HOPPER_GA_SCALE) runtime.kind=$(HOPPER_GA_RUNTIME) output_root=$(HOPPER_GA_OUT)/runs $(LAUNCH)
	$(CHARCTL) train hopper-ga speed=5 beta=0.5 scale=$(HOPPER_GA_SCALE) runtime.kind=$(HOPPER_GA_RUNTIME) output_root=$(HOPPER_GA_OUT)/runs
	$(PY) -m charctl.experiments.hopper_ga.evaluate $(HOPPER_GA_OUT)/runs/hopper-ga -o $(HOPPER_GA_OUT) --media
	@echo "report: $(HOPPER_GA_OUT)/report.md"

bench-hopper-ga: install ## hopper-ga: GA wall time of 100 x 100 per runtime (local, process, ray)
	$(PY) scripts/bench_hopper_ga.py
