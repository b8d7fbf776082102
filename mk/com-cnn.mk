# com-cnn reproduction targets (included by the Makefile). Runs go under outputs/repro/com-cnn/runs/<variant>/.
COMCNN := outputs/repro/com-cnn
COMCNN_RUNS := $(COMCNN)/runs

.PHONY: repro-com-cnn repro-com-cnn-table4

repro-com-cnn: install ## com-cnn: train the paper's best setting + history-only baseline + causal variant (scale=small, ~10 min), evaluate (NN baseline too), write outputs/repro/com-cnn/report.md
	$(CHARCTL) train com-cnn scale=small output_root=$(COMCNN_RUNS)/best
	$(CHARCTL) train com-cnn scale=small model.use_com=false output_root=$(COMCNN_RUNS)/history_only
	$(CHARCTL) train com-cnn scale=small data.frame=root_prev output_root=$(COMCNN_RUNS)/root_prev
	B=$$(ls -d $(COMCNN_RUNS)/best/com-cnn/*/ | tail -1); H=$$(ls -d $(COMCNN_RUNS)/history_only/com-cnn/*/ | tail -1); \
	P=$$(ls -d $(COMCNN_RUNS)/root_prev/com-cnn/*/ | tail -1); \
	rm -f $(COMCNN)/report.md; \
	$(CHARCTL) eval $$B $$H $$P --pose-error --dtw -o $(COMCNN) && \
	$(CHARCTL) export $$B --com-path circle:r=2,speed=1.2 --crouch-at 6 --seconds 10 --bvh $(COMCNN)/circle_crouch.bvh --video $(COMCNN)/circle_crouch.mp4 && \
	$(CHARCTL) export $$P --com-path circle:r=2,speed=1.2 --crouch-at 6 --seconds 10 --bvh $(COMCNN)/circle_crouch_root_prev.bvh
	@echo "report: $(COMCNN)/report.md"

repro-com-cnn-table4: install ## com-cnn: the paper's four Table 4 settings (history 15/90, kernel 2/10, 1 or 3 layers) at scale=small, one table
	$(CHARCTL) train com-cnn scale=small -m data.history=15 model.kernel=2 "model.channels=[32],[8,16,32]" output_root=$(COMCNN_RUNS)/table4 $(LAUNCH)
	$(CHARCTL) train com-cnn scale=small -m data.history=90 model.kernel=10 "model.channels=[128],[32,64,128]" output_root=$(COMCNN_RUNS)/table4 $(LAUNCH)
	rm -f $(COMCNN)/table4/report.md; \
	$(CHARCTL) eval $$(ls -d $(COMCNN_RUNS)/table4/com-cnn/*/ | tail -4) --pose-error -o $(COMCNN)/table4
	@echo "report: $(COMCNN)/table4/report.md"
