# cgail reproduction targets (included by the Makefile).
CGAIL_SMALL := outputs/repro/cgail-small
CGAIL_PAPER := outputs/repro/cgail-paper

.PHONY: repro-cgail-small repro-cgail-paper demo-cgail

repro-cgail-small: install ## cgail: train cGAIL + AMP baseline at scale=small, evaluate, write outputs/repro/cgail-small/report.md
	$(CHARCTL) train cgail scale=small output_root=$(CGAIL_SMALL)/cgail
	$(CHARCTL) train cgail scale=small cgail.conditional=false output_root=$(CGAIL_SMALL)/amp
	C=$$(ls -d $(CGAIL_SMALL)/cgail/cgail/*/ | tail -1); A=$$(ls -d $(CGAIL_SMALL)/amp/cgail/*/ | tail -1); \
	rm -f $(CGAIL_SMALL)/report.md; \
	$(CHARCTL) eval $$C $$A --dtw --confusion --switch walk right_kick --curves -k 4 -o $(CGAIL_SMALL)
	@echo "report: $(CGAIL_SMALL)/report.md"

repro-cgail-paper: install ## cgail: the paper's runs (10 skills, AMP, LS ablation, 1/3/6 skills); GPU/cluster scale
	$(CHARCTL) train cgail scale=paper output_root=$(CGAIL_PAPER)/cgail
	$(CHARCTL) train cgail scale=paper cgail.conditional=false output_root=$(CGAIL_PAPER)/amp
	$(CHARCTL) train cgail scale=paper cgail.class_loss=ls output_root=$(CGAIL_PAPER)/ls
	$(CHARCTL) train cgail scale=paper -m "use_skills=[walk],[walk,run,right_kick],[walk,run,jump,right_punch,right_kick,left_kick]" output_root=$(CGAIL_PAPER)/skills
	C=$$(ls -d $(CGAIL_PAPER)/cgail/cgail/*/ | tail -1); A=$$(ls -d $(CGAIL_PAPER)/amp/cgail/*/ | tail -1); L=$$(ls -d $(CGAIL_PAPER)/ls/cgail/*/ | tail -1); \
	rm -f $(CGAIL_PAPER)/report.md; \
	$(CHARCTL) eval $$C $$A --dtw --confusion --switch right_kick left_kick -k 8 -o $(CGAIL_PAPER) && \
	$(CHARCTL) eval $$C $$A $$L $(CGAIL_PAPER)/skills/cgail/*/ --curves -o $(CGAIL_PAPER)
	@echo "report: $(CGAIL_PAPER)/report.md"

demo-cgail: install ## cgail: a short training run (~5-10 min on 2 cores), its evaluation and a video
	$(CHARCTL) train cgail scale=small train.total_samples=150000 output_root=outputs/demo
	R=$$(ls -d outputs/demo/cgail/*/ | tail -1); \
	$(CHARCTL) eval $$R --dtw --confusion --curves -k 2 -o outputs/demo/eval && \
	$(CHARCTL) export $$R --video outputs/demo/cgail_rollout.mp4 --commands "walk:0,run:2,right_kick:4" --seconds 6
