# cgail reproduction targets (included by the Makefile).
CGAIL_SMALL := outputs/repro/cgail-small
CGAIL_PAPER := outputs/repro/cgail-paper
# The shipped amp-walk and tracking-walk (and the removed cgail-3skill) were trained before the small preset moved to
# 150 Hz physics with 0.05 joint armature (docs/cgail.md, "Throughput"): reproduce them at their rate.
CGAIL_300HZ := env.physics_hz=300 env.armature=0.01
# All four shipped policies were trained before the small preset's PPO update moved to bf16 where the
# hardware has it (ppo.update_precision=auto): reproduce them with their fp32 update.
CGAIL_FP32 := ppo.update_precision=fp32
# All shipped policies were trained before the small preset overlapped the rollout with the updates
# (train.overlap_update=true): reproduce them with the loop in turn.
CGAIL_INTURN := train.overlap_update=false
# The paper's reward and termination at small scale: the small preset carries the fidelity recipe since
# 2026-12-03 (conf/preset/cgail/small.yaml); `~key` deletes the preset's value, so the schema's (the paper's) applies.
CGAIL_PAPER_RECIPE := ~disc.style_head ~disc.wrong_skill_fakes ~cgail.class_on_policy ~reward.w_style ~reward.w_class \
	~reward.class_form ~reward.low_style_threshold ~reward.pose_error_threshold ~reward.w_track ~env.phase_obs \
	~env.skill_fall_weight ~ppo.desired_kl ~ppo.lr_max
# The settings repro-cgail-small trains with; repro-cgail-current empties it to train at the current preset.
CGAIL_SHIPPED := $(CGAIL_300HZ) $(CGAIL_FP32) $(CGAIL_INTURN) $(CGAIL_PAPER_RECIPE)

# The policy `make demo` shows, and its command schedule (seconds): each skill held 4-5 s, so the kick
# (a 1.5-s clip) is done after the 60-frame (2-s) command ramp ends.
CGAIL_DEMO_POLICY := pretrained/cgail-3skill-fidelity
CGAIL_DEMO_SCHEDULE := walk:0,run:4,right_kick:8

.PHONY: repro-cgail-small repro-cgail-current repro-cgail-paper demo-cgail

# The fidelity recipe's 3-skill runs (docs/cgail.md, "Fidelity recipe"), trained before the small preset carried the
# recipe, so their targets start from the paper's keys ($(CGAIL_PAPER_RECIPE)) and set each run's own: A = per-skill style head, wrong-skill
# fakes, class head on demonstrations only (w_S 0.8, w_C 0.2, r_C = P(command)), KL-targeting PPO rate; B = A's
# run forked at its 5,005,312-sample checkpoint and continued with early termination on a low style reward to
# 23,724,032 samples; C = B continued with early termination on a large pose error (0.5 m) to 4e7 samples;
# D = C continued with a tracking reward against that reference (w_T 0.5) to 46,579,712 samples.
CGAIL_FID := outputs/repro/cgail-fidelity
CGAIL_FID_RECIPE := disc.style_head=per_skill disc.wrong_skill_fakes=0.25 cgail.class_on_policy=false reward.w_style=0.8 reward.w_class=0.2 reward.class_form=prob ppo.desired_kl=0.02 ppo.lr_max=1e-4 train.checkpoint_every=20 train.keep_checkpoint_every=2500000 seed=1
CGAIL_FID_SAMPLES ?= 40000000
# The evaluations each 3-skill and ten-skill run below gets: $(call cgail-evaluate,RUN_DIR), then the targets they meet
# (RUN_DIR/eval/targets.md, scripts/check_targets_cgail.py).
cgail-evaluate = $(CHARCTL) eval $(1) --fidelity -k 4 && $(CHARCTL) eval $(1) --survival 5 -k 32 && $(CHARCTL) eval $(1) --dtw --confusion --switch walk right_kick -k 8 && $(PY) scripts/check_targets_cgail.py $(1)/eval --out $(1)/eval/targets.md

.PHONY: repro-cgail-fidelity
repro-cgail-fidelity: install ## cgail: the fidelity recipe's runs A to E (3 skills, 8e7 samples; ~7 h on 2 cores) = pretrained/cgail-3skill-fidelity, with its evaluations
	$(CHARCTL) train cgail scale=small $(CGAIL_PAPER_RECIPE) $(CGAIL_FID_RECIPE) train.total_samples=5005312 output_root=$(CGAIL_FID)/A
	A=$$(ls -d $(CGAIL_FID)/A/cgail/*/ | tail -1); B=$(CGAIL_FID)/B/cgail/$$(basename $$A); \
	mkdir -p $$B/checkpoints && cp $$A/config.yaml $$B/ && cp $$A/checkpoints/last.pt $$B/checkpoints/last.pt && \
	$(CHARCTL) train cgail --resume $$A train.total_samples=7500000 && \
	$(CHARCTL) train cgail --resume $$B reward.low_style_threshold=0.05 reward.low_style_steps=10 train.fidelity_every=1000000 train.total_samples=23724032 && \
	C=$(CGAIL_FID)/C/cgail/$$(basename $$A); mkdir -p $$C && cp -r $$B/config.yaml $$B/checkpoints $$B/tb $$C/ && \
	$(CHARCTL) train cgail --resume $$C reward.pose_error_threshold=0.5 train.total_samples=$(CGAIL_FID_SAMPLES) && \
	$(CHARCTL) eval $$B --checkpoints --rank fidelity && $(CHARCTL) eval $$C --checkpoints --rank fidelity && \
	D=$(CGAIL_FID)/D/cgail/$$(basename $$A); mkdir -p $$D/checkpoints && cp -r $$C/config.yaml $$C/tb $$D/ && cp $$C/checkpoints/last.pt $$D/checkpoints/ && \
	$(CHARCTL) train cgail --resume $$D reward.w_track=0.5 train.total_samples=46579712 && $(CHARCTL) eval $$D --fidelity --survival 5 -k 4 && \
	E=$(CGAIL_FID)/E/cgail/$$(basename $$A); mkdir -p $$E/checkpoints && cp -r $$D/config.yaml $$D/tb $$E/ && cp $$D/checkpoints/last.pt $$E/checkpoints/ && \
	$(CHARCTL) train cgail --resume $$E env.skill_fall_weight=0.5 reward.w_track=1.0 train.total_samples=80000000 && \
	$(call cgail-evaluate,$$E)

# The whole recipe from the first sample, one run (docs/cgail.md, "Run G"): A's keys plus B's low-style termination,
# C's pose-error termination, D/E's tracking reward (w_T 1.0) and E's fall-weighted commands.
CGAIL_FID_FULL := $(CGAIL_FID_RECIPE) reward.low_style_threshold=0.05 reward.low_style_steps=10 reward.pose_error_threshold=0.5 reward.w_track=1.0 env.skill_fall_weight=0.5

.PHONY: repro-cgail-fidelity-one-run repro-cgail-10skill-fidelity
repro-cgail-fidelity-one-run: install ## cgail: the fidelity recipe from scratch in one run (3 skills, 4e7 samples; ~1.9 h on 2 cores), every kept checkpoint evaluated, the chosen one evaluated in full
	$(CHARCTL) train cgail scale=small $(CGAIL_PAPER_RECIPE) $(CGAIL_FID_FULL) train.total_samples=$(CGAIL_FID_SAMPLES) output_root=$(CGAIL_FID)/G
	G=$$(ls -d $(CGAIL_FID)/G/cgail/*/ | tail -1); \
	$(CHARCTL) eval $$G --checkpoints --after 10000000 -k 32 && \
	$(call cgail-evaluate,$$G)

# Run H (docs/cgail.md, "Run H"): run G's command plus the clip phase in the policy state (env.phase_obs=true).
.PHONY: repro-cgail-fidelity-phase
repro-cgail-fidelity-phase: install ## cgail: run G plus the clip phase in the policy state (3 skills, 4e7 samples; ~1.9 h on 2 cores), evaluated
	$(CHARCTL) train cgail scale=small $(CGAIL_PAPER_RECIPE) $(CGAIL_FID_FULL) env.phase_obs=true train.total_samples=$(CGAIL_FID_SAMPLES) output_root=$(CGAIL_FID)/H
	H=$$(ls -d $(CGAIL_FID)/H/cgail/*/ | tail -1); \
	$(CHARCTL) eval $$H --checkpoints --after 10000000 -k 32 && \
	$(call cgail-evaluate,$$H)

repro-cgail-10skill-fidelity: install ## cgail: run H's recipe (G's plus the clip phase) on all ten skills (1.5e8 samples, the paper's budget; ~6 h on 2 cores, resumable with --resume), every kept checkpoint evaluated
	$(CHARCTL) train cgail scale=small "use_skills=[]" $(CGAIL_PAPER_RECIPE) $(CGAIL_FID_FULL) env.phase_obs=true train.fidelity_every=2000000 train.total_samples=150000000 output_root=$(CGAIL_FID)/ten
	T=$$(ls -d $(CGAIL_FID)/ten/cgail/*/ | tail -1); \
	$(CHARCTL) eval $$T --checkpoints --after 50000000 -k 16 && $(CHARCTL) eval $$T --fidelity -k 4

# The same run on a GPU (MuJoCo Warp; the env rules of the recipe run there since 2026-12-03): 4,096 envs,
# so each PPO iteration takes 131,072 samples. Not yet run on a GPU: no device was lent when it was written;
# tests/test_gpu_path.py trains the recipe's env rules on Warp-CPU at smoke scale.
.PHONY: repro-cgail-10skill-fidelity-gpu
repro-cgail-10skill-fidelity-gpu: install ## cgail: repro-cgail-10skill-fidelity on a CUDA GPU (env.backend=warp, 4,096 envs), every kept checkpoint evaluated
	$(CHARCTL) train cgail scale=small "use_skills=[]" $(CGAIL_PAPER_RECIPE) $(CGAIL_FID_FULL) env.phase_obs=true env.backend=warp device=cuda env.num_envs=4096 train.fidelity_every=5000000 train.total_samples=150000000 output_root=$(CGAIL_FID)/ten-gpu
	T=$$(ls -d $(CGAIL_FID)/ten-gpu/cgail/*/ | tail -1); \
	$(CHARCTL) eval $$T --checkpoints --after 50000000 -k 16 device=cpu && $(CHARCTL) eval $$T --fidelity -k 4 device=cpu

.PHONY: repro-cgail-tracking-3skill
repro-cgail-tracking-3skill: install ## cgail: the multi-skill tracking baseline (walk, run, right_kick; command and phase in the state; 4e7 samples, ~80 min on 2 cores) = pretrained/tracking-3skill, evaluated
	$(CHARCTL) train cgail reward.kind=tracking env.switch_prob=0 train.total_samples=$(CGAIL_FID_SAMPLES) train.checkpoint_every=20 train.keep_checkpoint_every=2500000 seed=1 output_root=$(CGAIL_FID)/tracking
	T=$$(ls -d $(CGAIL_FID)/tracking/cgail/*/ | tail -1); $(CHARCTL) eval $$T --fidelity -k 4 && $(CHARCTL) eval $$T --survival 5 -k 32 && $(CHARCTL) eval $$T --dtw -k 8

# The flight experiment (docs/cgail.md, "Flight"): the recipe on walk, run and jump with a 0.15-m root-height radius
# in the pose-error check, so a jump done on the ground ends at the clip's flight.
.PHONY: repro-cgail-flight
repro-cgail-flight: install ## cgail: the recipe plus reward.root_height_threshold=0.15 on walk, run, jump (2.5e7 samples; ~50 min on 2 cores), evaluated
	$(CHARCTL) train cgail "use_skills=[walk,run,jump]" reward.root_height_threshold=0.15 train.total_samples=25000000 train.checkpoint_every=20 train.keep_checkpoint_every=2500000 seed=1 output_root=$(CGAIL_FID)/flight
	F=$$(ls -d $(CGAIL_FID)/flight/cgail/*/ | tail -1); $(CHARCTL) eval $$F --fidelity -k 4 && $(CHARCTL) eval $$F --survival 5 -k 32 && $(CHARCTL) eval $$F --dtw -k 8

# Ten skills with a moving walk reference (docs/cgail.md, "Walk: a reference that moves on"): the radii run's command
# plus reward.goal_reference_window=3, so walk and run are scored against a reference that advances 1-3 clip frames
# per control step from the matched frame instead of the closest frame anywhere (which the radii run's shuffle passes).
# Started 2026-12-03 22:05; continued with --resume from pretrained/in-progress/ (~5 h on 2 cores in all).
.PHONY: repro-cgail-10skill-window
repro-cgail-10skill-window: install ## cgail: ten skills, both radii plus reward.goal_reference_window=3 (1.5e8 samples; ~5 h on 2 cores, resumable), evaluated
	$(CHARCTL) train cgail "use_skills=[]" reward.root_height_threshold=0.15 reward.yaw_error_threshold=1.5 reward.goal_reference_window=3 train.fidelity_every=2000000 train.total_samples=150000000 train.checkpoint_every=20 train.keep_checkpoint_every=2500000 seed=1 output_root=$(CGAIL_FID)/window
	T=$$(ls -d $(CGAIL_FID)/window/cgail/*/ | tail -1); \
	$(call cgail-evaluate,$$T)

# Failure-weighted start frames on the finished window run (docs/cgail.md, "Spindance"): 3e7 more samples from its
# 1.5e8 checkpoint with env.start_failure_weight=0.5 (half the starts drawn just before where episodes end). Past the
# paper's budget: a probe of whether spindance moves when its episodes start before its arm sweep, against the window
# run's own flat last 5e7 samples. The 2026-12-04 run resumed the full run folder (optimisers and replay kept); this
# target resumes a copy of the committed inference-only folder (in git at CGAIL_WINDOW_COMMIT since it left
# pretrained/in-progress/ on 2026-12-05), so its optimisers start fresh.
CGAIL_WINDOW_COMMIT := be5e0ae
.PHONY: repro-cgail-10skill-start-frames
repro-cgail-10skill-start-frames: install ## cgail: the window run's 1.5e8 checkpoint continued 3e7 samples with failure-weighted start frames (~1.1 h on 2 cores), evaluated
	rm -rf $(CGAIL_FID)/start-frames && mkdir -p $(CGAIL_FID)/start-frames && git archive $(CGAIL_WINDOW_COMMIT) pretrained/in-progress/cgail-10skill-window | tar -x --strip-components=3 -C $(CGAIL_FID)/start-frames && rm -rf $(CGAIL_FID)/start-frames/eval
	$(CHARCTL) train cgail --resume $(CGAIL_FID)/start-frames env.start_failure_weight=0.5 train.total_samples=180000000
	T=$(CGAIL_FID)/start-frames; \
	$(CHARCTL) eval $$T --checkpoints --after 150000001 -k 8 --confusion-k 4 && $(CHARCTL) eval $$T --fidelity -k 4 && $(CHARCTL) eval $$T --survival 5 -k 16

# The tracking weight that learned spindance alone (docs/cgail.md, "Spindance": reward.w_track=4.0 on the small
# preset, coverage 0.857 at 1.64e7 samples), first on run H's three skills (does it keep their targets?), then on the
# window run's ten skills (both radii and the moving walk reference kept, for the jump's flight and the walk's stride).
.PHONY: repro-cgail-3skill-track4
repro-cgail-3skill-track4: install ## cgail: run H's command with reward.w_track=4.0 (4e7 samples; ~75 min on 2 cores), evaluated
	$(CHARCTL) train cgail reward.w_track=4.0 train.total_samples=$(CGAIL_FID_SAMPLES) train.checkpoint_every=20 train.keep_checkpoint_every=2500000 seed=1 output_root=$(CGAIL_FID)/track4-3skill
	T=$$(ls -d $(CGAIL_FID)/track4-3skill/cgail/*/ | tail -1); \
	$(call cgail-evaluate,$$T)

# Run H's command (the small preset) at a second seed, and the same with the moving walk reference of the ten-skill
# runs (docs/cgail.md, "Run H at a second seed").
.PHONY: repro-cgail-3skill-seed2 repro-cgail-3skill-window-seed2
repro-cgail-3skill-seed2: install ## cgail: run H's command at seed 2 (3 skills, 4e7 samples; ~70 min on 2 cores), evaluated
	$(CHARCTL) train cgail train.total_samples=$(CGAIL_FID_SAMPLES) train.checkpoint_every=20 train.keep_checkpoint_every=2500000 seed=2 output_root=$(CGAIL_FID)/H-seed2
	S=$$(ls -d $(CGAIL_FID)/H-seed2/cgail/*/ | tail -1); \
	$(call cgail-evaluate,$$S)

repro-cgail-3skill-window-seed2: install ## cgail: run H's command at seed 2 with the moving walk reference, reward.goal_reference_window=3 (4e7 samples; ~70 min on 2 cores), evaluated
	$(CHARCTL) train cgail reward.goal_reference_window=3 train.total_samples=$(CGAIL_FID_SAMPLES) train.checkpoint_every=20 train.keep_checkpoint_every=2500000 seed=2 output_root=$(CGAIL_FID)/H-window-seed2
	W=$$(ls -d $(CGAIL_FID)/H-window-seed2/cgail/*/ | tail -1); \
	$(call cgail-evaluate,$$W)

# Table 6.1's AMP column on three skills: the small preset's recipe without the command (cgail.conditional=false:
# no class head, one style logit, no command in the state; the tracking reward, the terminations and the phase kept),
# with env.switch_prob=0 because a switch the policy cannot see would only end its episodes (docs/cgail.md,
# "A multi-skill AMP baseline"). And run H's command with the moving walk reference at run H's own seed, to separate
# the window's effect on the kick from the seed's ("Run H at a second seed").
.PHONY: repro-cgail-3skill-amp repro-cgail-3skill-window
repro-cgail-3skill-amp: install ## cgail: AMP baseline on walk, run, right_kick = the small preset without the command (4e7 samples; ~70 min on 2 cores), evaluated
	$(CHARCTL) train cgail cgail.conditional=false env.switch_prob=0 train.total_samples=$(CGAIL_FID_SAMPLES) train.checkpoint_every=20 train.keep_checkpoint_every=2500000 seed=1 output_root=$(CGAIL_FID)/amp-3skill
	M=$$(ls -d $(CGAIL_FID)/amp-3skill/cgail/*/ | tail -1); \
	$(CHARCTL) eval $$M --fidelity -k 4 && $(CHARCTL) eval $$M --survival 5 -k 32 && $(CHARCTL) eval $$M --dtw -k 8

repro-cgail-3skill-window: install ## cgail: run H's command with reward.goal_reference_window=3 at seed 1 (4e7 samples; ~70 min on 2 cores), evaluated
	$(CHARCTL) train cgail reward.goal_reference_window=3 train.total_samples=$(CGAIL_FID_SAMPLES) train.checkpoint_every=20 train.keep_checkpoint_every=2500000 seed=1 output_root=$(CGAIL_FID)/H-window
	W=$$(ls -d $(CGAIL_FID)/H-window/cgail/*/ | tail -1); \
	$(call cgail-evaluate,$$W)

.PHONY: repro-cgail-10skill-track4
repro-cgail-10skill-track4: install ## cgail: the window run's ten-skill command with reward.w_track=4.0 (1.5e8 samples; ~5 h on 2 cores, resumable), evaluated
	$(CHARCTL) train cgail "use_skills=[]" reward.w_track=4.0 reward.root_height_threshold=0.15 reward.yaw_error_threshold=1.5 reward.goal_reference_window=3 train.fidelity_every=2000000 train.total_samples=150000000 train.checkpoint_every=20 train.keep_checkpoint_every=2500000 seed=1 output_root=$(CGAIL_FID)/track4-10skill
	T=$$(ls -d $(CGAIL_FID)/track4-10skill/cgail/*/ | tail -1); \
	$(call cgail-evaluate,$$T)

# The tracking weight only where the style reward holds a skill back (docs/cgail.md, "Spindance": w_track = 4 for
# every skill delays the kick and shortens the walk on three skills; on spindance alone it learns the dance, with or
# without the radii; on breakdance alone it was slightly ahead at 6e6 samples): the window run's ten-skill command with
# reward.w_track_skills={spindance:4.0,breakdance:4.0}, the other eight at w_track = 1. Started 2026-12-05 and continued
# with --resume (~5 h 20 min on 2 cores in all); its 1.5e8 checkpoint is pretrained/cgail-10skill-track-skills.
.PHONY: repro-cgail-10skill-track-skills
repro-cgail-10skill-track-skills: install ## cgail: the window run's ten-skill command with w_track 4 for spindance and breakdance (1.5e8 samples; ~5 h on 2 cores, resumable; = pretrained/cgail-10skill-track-skills), evaluated
	$(CHARCTL) train cgail "use_skills=[]" "reward.w_track_skills={spindance:4.0,breakdance:4.0}" reward.root_height_threshold=0.15 reward.yaw_error_threshold=1.5 reward.goal_reference_window=3 train.fidelity_every=2000000 train.total_samples=150000000 train.checkpoint_every=20 train.keep_checkpoint_every=2500000 seed=1 output_root=$(CGAIL_FID)/track-skills
	T=$$(ls -d $(CGAIL_FID)/track-skills/cgail/*/ | tail -1); \
	$(call cgail-evaluate,$$T)

# The shipped ten-skill command with the mirror loss on the mirrored pairs from the first sample and breakdance's
# tracking weight at 8 (docs/cgail.md, "Ten skills from scratch with the mirror loss"): the mirror fine-tune made the
# kicks symmetric, and w_T 8 is the only change that lifted breakdance past 0.5, both only late in a run. Started
# 2026-12-07; ~12.7 h at this AMD machine's 3.3k samples/s, so it is continued across sessions with --resume from
# pretrained/in-progress/cgail-10skill-mirror (scripts/package_pretrained.py --bf16-moments). At 84,049,920 samples
# (2026-12-08) neither kick nor the spinkick was performed (kicking feet ~0.2 m in training from 7.4e7, where the
# shipped run's reached 0.6-1.3 m), so the loss was switched off for the rest: `--resume RUN ppo.mirror_loss=0.0`.
.PHONY: repro-cgail-10skill-mirror
repro-cgail-10skill-mirror: install ## cgail: the shipped ten-skill command plus breakdance's w_track 8 and ppo.mirror_loss=1 for the first 8.4e7 samples, then 0 (1.5e8 samples; ~13 h on 2 cores, resumable), evaluated
	$(CHARCTL) train cgail "use_skills=[]" "reward.w_track_skills={spindance:4.0,breakdance:8.0}" reward.root_height_threshold=0.15 reward.yaw_error_threshold=1.5 reward.goal_reference_window=3 ppo.mirror_loss=1.0 train.fidelity_every=2000000 train.total_samples=84049920 train.checkpoint_every=20 train.keep_checkpoint_every=2500000 seed=1 output_root=$(CGAIL_FID)/mirror-10skill
	T=$$(ls -d $(CGAIL_FID)/mirror-10skill/cgail/*/ | tail -1); \
	$(CHARCTL) train cgail --resume $$T ppo.mirror_loss=0.0 train.total_samples=150000000 && \
	$(call cgail-evaluate,$$T)

# Ten skills with both radii (docs/cgail.md, "Ten skills with a root-height and a heading radius"): the flight experiment's
# root-height radius plus reward.yaw_error_threshold=1.5 (the spins must turn), run H's recipe otherwise. Started
# 2026-12-03 and continued with --resume from pretrained/in-progress/ (~5 h on 2 cores in all).
.PHONY: repro-cgail-10skill-radii
repro-cgail-10skill-radii: install ## cgail: ten skills with the root-height (0.15 m) and heading (1.5 rad) radii (1.5e8 samples; ~5 h on 2 cores, resumable), evaluated
	$(CHARCTL) train cgail "use_skills=[]" reward.root_height_threshold=0.15 reward.yaw_error_threshold=1.5 train.fidelity_every=2000000 train.total_samples=150000000 train.checkpoint_every=20 train.keep_checkpoint_every=2500000 seed=1 output_root=$(CGAIL_FID)/radii
	T=$$(ls -d $(CGAIL_FID)/radii/cgail/*/ | tail -1); \
	$(call cgail-evaluate,$$T)

# The tracking baseline over all ten skills (Table 6.1's third column for every skill). ~4.6 h on 2 cores at the cGAIL
# run's budget (9.0k samples/s measured); started 2026-12-04 and paused at 8.6e6 samples (outputs/ only, lost);
# re-started 2026-12-05 10:07, stopped at 5.89e7 (10.4k samples/s alone), continued to 8.12e7 and, 15:13-17:33 with
# one pause, to 1.5e8 (~10k samples/s alone): pretrained/tracking-10skill. The three-skill one is
# pretrained/tracking-3skill. docs/cgail.md "Spindance": a tracking run ended at the pose check
# (reward.pose_error_threshold=0.5) learns what this one, without it, may not.
.PHONY: repro-cgail-tracking-10skill
repro-cgail-tracking-10skill: install ## cgail: the multi-skill tracking baseline on all ten skills (1.5e8 samples, ~4 h on 2 cores, resumable; = pretrained/tracking-10skill), evaluated
	$(CHARCTL) train cgail "use_skills=[]" reward.kind=tracking env.switch_prob=0 train.fidelity_every=2000000 train.total_samples=150000000 train.checkpoint_every=20 train.keep_checkpoint_every=2500000 seed=1 output_root=$(CGAIL_FID)/tracking10
	T=$$(ls -d $(CGAIL_FID)/tracking10/cgail/*/ | tail -1); \
	$(CHARCTL) eval $$T --fidelity -k 4 && $(CHARCTL) eval $$T --survival 5 -k 32 && $(CHARCTL) eval $$T --dtw -k 8

repro-cgail-small: install ## cgail: the shipped policies' runs (pretrained/README.md: cGAIL 3 skills, AMP and tracking walk; ~3 h on 2 cores), evaluated
	$(CHARCTL) train cgail scale=small train.total_samples=8000000 $(CGAIL_SHIPPED) seed=1 output_root=$(CGAIL_SMALL)/cgail
	$(CHARCTL) train cgail scale=small use_skills=[walk] cgail.conditional=false train.total_samples=2000000 $(CGAIL_SHIPPED) seed=1 output_root=$(CGAIL_SMALL)/amp
	$(CHARCTL) train cgail scale=small use_skills=[walk] cgail.conditional=false reward.kind=tracking train.total_samples=1500000 $(CGAIL_SHIPPED) seed=1 output_root=$(CGAIL_SMALL)/tracking
	C=$$(ls -d $(CGAIL_SMALL)/cgail/cgail/*/ | tail -1); A=$$(ls -d $(CGAIL_SMALL)/amp/cgail/*/ | tail -1); \
	T=$$(ls -d $(CGAIL_SMALL)/tracking/cgail/*/ | tail -1); \
	rm -f $(CGAIL_SMALL)/report.md; \
	$(CHARCTL) eval $$C --survival 5 --confusion --switch walk right_kick --curves -k 8 -o $(CGAIL_SMALL) && \
	$(CHARCTL) eval $$C $$A $$T --survival 10 --dtw -k 8 -o $(CGAIL_SMALL)
	@echo "report: $(CGAIL_SMALL)/report.md"

repro-cgail-current: install ## cgail: repro-cgail-small's three runs at the current small preset (150 Hz physics, bf16 PPO update, overlapped loop; docs/cgail.md "Throughput"; ~45 min on 2 cores), evaluated
	$(MAKE) --no-print-directory repro-cgail-small CGAIL_SHIPPED= CGAIL_SMALL=outputs/repro/cgail-current

repro-cgail-paper: install ## cgail: the paper's runs (10 skills, AMP, LS ablation, 1/3/6 skills); GPU/cluster scale
	$(CHARCTL) train cgail scale=paper output_root=$(CGAIL_PAPER)/cgail
	$(CHARCTL) train cgail scale=paper cgail.conditional=false output_root=$(CGAIL_PAPER)/amp
	$(CHARCTL) train cgail scale=paper cgail.class_loss=ls output_root=$(CGAIL_PAPER)/ls
	$(CHARCTL) train cgail scale=paper -m "use_skills=[walk],[walk,run,right_kick],[walk,run,jump,right_punch,right_kick,left_kick]" output_root=$(CGAIL_PAPER)/skills $(LAUNCH)
	C=$$(ls -d $(CGAIL_PAPER)/cgail/cgail/*/ | tail -1); A=$$(ls -d $(CGAIL_PAPER)/amp/cgail/*/ | tail -1); L=$$(ls -d $(CGAIL_PAPER)/ls/cgail/*/ | tail -1); \
	rm -f $(CGAIL_PAPER)/report.md; \
	$(CHARCTL) eval $$C $$A --dtw --confusion --switch right_kick left_kick -k 8 -o $(CGAIL_PAPER) && \
	$(CHARCTL) eval $$C $$A $$L $(CGAIL_PAPER)/skills/cgail/*/ --curves -o $(CGAIL_PAPER)
	@echo "report: $(CGAIL_PAPER)/report.md"

demo-cgail: install ## cgail: a short training run (~2 min), then the shipped 3-skill policy evaluated (survival, confusion, fidelity with filmstrips) and rendered switching walk -> run -> right_kick
	$(CHARCTL) train cgail scale=small train.total_samples=100000 output_root=outputs/demo
	$(CHARCTL) eval $(CGAIL_DEMO_POLICY) --survival 5 --confusion --fidelity -k 2 -o outputs/demo/eval
	$(CHARCTL) export $(CGAIL_DEMO_POLICY) --video outputs/demo/cgail_switch.mp4 --commands "$(CGAIL_DEMO_SCHEDULE)" --seconds 13

# Spindance probes (docs/cgail.md, "Spindance"): tracking with the pose check (learns the arm's pass in ~4e6 samples),
# and the small preset's recipe on spindance alone with and without its style reward and with reward.w_track=4. One
# skill, seed 1, 6e6 samples each (~12 min apiece on 2 cores).
.PHONY: repro-cgail-spindance-probes
repro-cgail-spindance-probes: install ## cgail: spindance alone, tracking + pose check vs the recipe with / without its style reward and with w_track=4 (4 x 6e6 samples, ~50 min), evaluated
	$(CHARCTL) train cgail reward.kind=tracking "use_skills=[spindance]" cgail.conditional=false reward.pose_error_threshold=0.5 train.total_samples=6000000 train.fidelity_every=1000000 seed=1 output_root=$(CGAIL_FID)/spindance/tracking-term
	$(CHARCTL) train cgail "use_skills=[spindance]" train.total_samples=6000000 train.fidelity_every=1000000 seed=1 output_root=$(CGAIL_FID)/spindance/recipe
	$(CHARCTL) train cgail "use_skills=[spindance]" reward.w_style=0 train.total_samples=6000000 train.fidelity_every=1000000 seed=1 output_root=$(CGAIL_FID)/spindance/recipe-nostyle
	$(CHARCTL) train cgail "use_skills=[spindance]" reward.w_track=4.0 train.total_samples=6000000 train.fidelity_every=1000000 seed=1 output_root=$(CGAIL_FID)/spindance/recipe-track4
	for d in tracking-term recipe recipe-nostyle recipe-track4; do T=$$(ls -d $(CGAIL_FID)/spindance/$$d/cgail/*/ | tail -1); $(CHARCTL) eval $$T --fidelity -k 4 || exit 1; done
