//! Physical correction (MotionAug Sec. 3.3): a simulated humanoid learns, with
//! PPO, to imitate a clip under a PD-residual root force; the corrected clip is
//! what the simulated character actually does, never the reference copied through.
//!
//! * [`task`]: the physics imitation environment seen as a [`ppo::Env`].
//! * [`rollout`]: the deterministic whole-clip rollout that yields the corrected
//!   motion and the paper's figures (R_norm, mean reward, residual force ratio).
//! * [`acceptance`]: when a corrected clip is physically honest (no fall, mean
//!   reward, residual force, foot skating, feet on their soles), each criterion
//!   judged and reported.
//! * [`job`]: one correction job: train within a budget, evaluate, checkpoint,
//!   resume, and write the outputs.
//! * [`report`]: `report.json` and the learning-curve SVG.
//! * [`summary`]: the corrections of a class in one table (`motionaug bench correction`).
//! * [`class`]: one tracker policy for a class (it sees the upcoming
//!   reference frames), trained on many clips; every clip's correction starts
//!   from it (`[correct] policy = "class"`, `bench correction --tracker-clips`).
//!
//! ## Session 26 (2026-12-06): the originals within the time budget
//!
//! With a short class tracker (150 iterations) and every clip's fine-tuning
//! capped at 15 PPO iterations, kick, hop and deposit missed the 90 %
//! of originals (sessions 19 and 21: 86 %, 83 %, 59 %), and every rejected
//! one stopped at the cap, not at the 300 s budget the issue allows. The
//! originals are one correction in 21 of a class (10 IK edits and 10 VAE
//! samples each) and the debiaser's only pairs, so they now have their own
//! cap (`[correct] original_max_iterations`, `bench correction
//! --original-max-iterations`, `eval table --original-iterations`; default:
//! the variants' cap). Measured on one thread while an eval table ran on
//! the other core (`motionaug bench correction --data ../shared/data/hdm05
//! --classes C --per-class 100 --tracker-clips 100 --tracker-budget 1800
//! --tracker-iterations 150 --threads 1 --time-budget 300 --out OUT`, no
//! iteration cap; for kick also `--max-iterations 15` first, then the same
//! folder without the five rejected clips' folders and without the cap):
//!
//! | class | clips | class tracker s, as is | accepted, 15 iterations | **accepted, 300 s** | iterations of those past 15 | their s | residual / m g | R_norm | skating m/s | penetration mm | floating % | soles flat % | originals s in all |
//! |---|---|---|---|---|---|---|---|---|---|---|---|---|---|
//! | kick | 29 | 382, 11/29 | 24 (83 %) | **29 (100 %)** | 17-79 (5 clips) | 26-130 | 0.040 | 0.891 | 0.149 -> 0.049 | 3.1 -> 5.8 | 13 -> 1 | 80 -> 95 | 418 |
//! | hop | 36 | 403, 26/36 | 33 (92 %) | **36 (100 %)** | 23-62 (3) | 57-158 | 0.042 | 0.890 | 0.199 -> 0.034 | 0.9 -> 5.9 | 53 -> 53 | 91 -> 99 | 443 |
//! | deposit | 32 | 404, 4/32 | 23 (72 %) | **32 (100 %)** | 18-150 (9) | 42-263 | 0.030 | 0.919 | 0.093 -> 0.027 | 2.4 -> 4.0 | 2 -> 1 | 83 -> 96 | 1,164 |
//! | squat | 52 | 365, 29/52 | 42 (81 %) | **49 (94 %)** | 16-151 (10) | 23-299 | 0.033 | 0.910 | 0.126 -> 0.048 | 2.4 -> 1.2 | 14 -> 3 | 45 -> 96 | 1,548 |
//!
//! (Runs are deterministic on one thread, so a clip that needed more than 15
//! iterations without the cap is one the cap rejects; kick's 24 was measured
//! with the cap.) Every original of kick, hop and deposit passes every
//! criterion within the budget: 97 of 97, the longest deposit's 263 s on a
//! shared core. Squat, the first time all 52 were corrected, passes 49: the
//! three rejected are actor bd's squats 008, 011, 012, whose captures skate
//! 0.33-0.44 m/s; their outputs skate 0.136-0.155 m/s (every other
//! criterion passes, R_norm 0.88-0.93) when the 300 s run out (104-151
//! iterations on a core shared three ways), above the 0.1 m/s cap. The
//! cost is small against a class: the clips past the cap add 552 s to
//! deposit's originals (1,164 s in all; the capped run would take about
//! 612, scaling each of those clips' time to 15 iterations), 0.8 s per
//! correction over deposit's 672 (session 21: 12.4 s per clip); 184 s for
//! hop and 145 s for kick, 0.2 s per correction of theirs; 1,104 s for
//! squat (the three rejected spend their whole budget), 1.0 s per
//! correction over a class of 52 x 21.
//!
//! ## Session 25 (2026-12-06): the same numbers on any thread count; two cores as two clips
//!
//! PPO now steps its environments in batches of `ppo::PpoConfig::rollout_batch`
//! (4) whatever its thread count (before, a thread batched its whole share,
//! so one rollout thread gave other bits than two). Side by side in one run
//! on the quiet machine, 6 kicks spread over the class, 8 PPO iterations each
//! from scratch, two rounds interleaved (`motionaug bench correction --data
//! ../shared/data/hdm05 --classes kick --per-class 6 --max-iterations 8
//! --threads T --clips-at-once C --out OUT`):
//!
//! | layout | elapsed s (round 1 / 2) | s per clip amortised | own s per clip |
//! |---|---|---|---|
//! | one clip at a time, 2 rollout threads | 38.9 / 40.4 | 6.6 | 6.6 |
//! | two clips at a time, 1 rollout thread each | 27.2 / 25.7 | 4.4 | 8.7 |
//!
//! Two clips at a time get **1.50x** the throughput of one clip on both cores,
//! and every clip's R_norm, residual force and criteria are identical in all
//! four runs (`tests/correct.rs`, `the_rollout_threads_do_not_change_a_correction`,
//! checks the simulated clip bit for bit). So corrections go side by side
//! (`eval table --threads`, `augment --correct-threads`, several workers)
//! and only a job that runs alone (a class tracker) takes both threads.
//!
//! ## Session 22 (2026-12-06): deposit's VAE samples from stronger trackers
//!
//! Session 21 left deposit's VAE samples at 31 % (99 of 320) behind a class
//! tracker of 150 PPO iterations that passed 6 of 32 originals as is. The
//! same VAE command (`vae train ../shared/data/hdm05/*deposit*.amc
//! --iterations 1500`, 2,994 s on one core; `vae sample --count 320 --seed
//! 1`), every fifth sample (64) corrected with trackers four and two times
//! longer: `taskset -c 1 motionaug bench correction --data
//! ../shared/data/hdm05 --classes deposit --per-class 4 --tracker-clips 100
//! --tracker-budget 1800 --tracker-iterations 600 --threads 1
//! --max-iterations 15 --time-budget 300 --variant-tracker-iterations 300
//! --variants vae/<every fifth>.npz --out bench` (`RAYON_NUM_THREADS=1`; the
//! other core ran an eval table, then the test suite):
//!
//! | | class tracker | originals as is | VAE samples as is (class, second tracker) | VAE accepted | falls | soles fail | residual / m g | s per sample |
//! |---|---|---|---|---|---|---|---|---|
//! | session 21 | 150 it, 189 s | 6/32 | 55/640 variants (IK + VAE), 190/585 | 99/320 (31 %) | 186 | 219 | 0.064 | ~12 (class mean) |
//! | session 22 | 600 it, 1,714 s | 22/32 | 2/64, 18/62 (300 it, 702 s) | **38/64 (59 %)** | 20 | 25 | 0.042 | 16 |
//!
//! Of the 26 rejected samples 20 fall (control steps 38-67 at 30 Hz, 1.3-2.2
//! s in, crouching to the floor), 5 keep their heels up (soles flat in 67-88
//! % of planted frames, 90 % needed) and one skates 0.023 m/s against its
//! input's 0.015. Plausibility of the 64:
//! skating 0.062 -> 0.030 m/s, penetration 1.1 -> 1.2 mm, soles flat 70 ->
//! 69 %. So the tracker's length is most of deposit's gap (31 -> 59 %, one
//! sample short of the 60 % target on this subset), and it costs: the two
//! trackers are 2,416 s for the class (3.6 s per clip over its 672
//! corrections) and a VAE sample 16 s of fine-tuning on average, so the
//! class would land near the 15 s per clip limit rather than at session
//! 21's 12.4 (not run whole: the cores went to the kick eval table).
//!
//! ## Session 21 (2026-12-05): grab, deposit and hop as whole classes; squat on a quarter
//!
//! Session 20's commands (one class per core, `taskset`, `RAYON_NUM_THREADS=1`),
//! with hop's and squat's new IK presets (`synth::ik::Preset::Hop`, `Squat`:
//! ours, not the paper's). Clippy, the CI run and debiasing experiments
//! shared the two cores for part of the time, so the wall times are upper
//! bounds.
//!
//! | class | clips | accepted | no fall | reward | residual | skating | soles | residual / m g | R_norm | skating m/s | penetration mm | floating % | soles flat % |
//! |---|---|---|---|---|---|---|---|---|---|---|---|---|---|
//! | grab originals | 29 | **27 (93 %)** | 29 | 29 | 29 | 29 | 27 | 0.017 | 0.958 | 0.111 -> 0.024 | 1.7 -> 2.3 | 5 -> 1 | 70 -> 98 |
//! | grab IK edits | 290 | **272 (94 %)** | 290 | 290 | 290 | 272 | 290 | 0.015 | 0.953 | 0.111 -> 0.032 | 1.7 -> 2.7 | 5 -> 0 | 70 -> 99 |
//! | grab VAE samples | 290 | **280 (97 %)** | 287 | 287 | 287 | 285 | 282 | 0.015 | 0.965 | 0.062 -> 0.011 | 0.1 -> 0.8 | 1 -> 1 | 80 -> 98 |
//! | hop originals | 36 | **30 (83 %)** | 36 | 36 | 36 | 35 | 31 | 0.047 | 0.873 | 0.199 -> 0.038 | 0.9 -> 5.9 | 53 -> 54 | 91 -> 96 |
//! | hop IK edits | 360 | **332 (92 %)** | 360 | 360 | 360 | 341 | 347 | 0.048 | 0.868 | 0.312 -> 0.041 | 0.9 -> 5.6 | 53 -> 57 | 91 -> 99 |
//! | hop VAE samples | 360 | **296 (82 %)** | 360 | 360 | 358 | 302 | 352 | 0.073 | 0.873 | 0.043 -> 0.021 | 0.3 -> 4.3 | 52 -> 38 | 95 -> 99 |
//! | deposit originals | 32 | **19 (59 %)** | 23 | 26 | 32 | 31 | 22 | 0.033 | 0.831 | 0.093 -> 0.024 | 2.4 -> 6.1 | 2 -> 2 | 83 -> 87 |
//! | deposit IK edits | 320 | **281 (88 %)** | 295 | 295 | 320 | 316 | 296 | 0.026 | 0.891 | 0.093 -> 0.026 | 2.5 -> 3.5 | 2 -> 0 | 83 -> 95 |
//! | deposit VAE samples | 320 | **99 (31 %)** | 134 | 138 | 231 | 263 | 101 | 0.064 | 0.634 | 0.074 -> 0.037 | 1.7 -> 0.8 | 2 -> 26 | 67 -> 55 |
//! | squat originals (13 of 52) | 13 | **12 (92 %)** | 13 | 13 | 13 | 13 | 12 | 0.028 | 0.919 | 0.108 -> 0.036 | 2.8 -> 1.2 | 10 -> 1 | 62 -> 96 |
//! | squat IK edits (of those 13) | 130 | **130 (100 %)** | 130 | 130 | 130 | 130 | 130 | 0.026 | 0.921 | 0.108 -> 0.038 | 2.8 -> 1.9 | 10 -> 2 | 62 -> 98 |
//! | squat VAE samples | 130 | **127 (98 %)** | 130 | 130 | 130 | 130 | 127 | 0.023 | 0.932 | 0.075 -> 0.027 | 0.8 -> 0.8 | 16 -> 0 | 39 -> 97 |
//!
//! | class | corrections | VAE training s | class tracker (150 its) s, originals as is | variants as is | second tracker (300 its) s, on, as is | clips s | class total s | **s per clip** |
//! |---|---|---|---|---|---|---|---|---|
//! | grab | 609 | 852 | 156, 18/29 | 384/580 | 443, 196, 130 | 922 | 2,403 | **3.9** |
//! | hop | 756 | 386 | 214, 22/36 | 263/720 | 509, 457, 280 | 2,263 | 3,394 | **4.5** |
//! | deposit | 672 | 1,393 | 189, 6/32 | 55/640 | 588, 585, 190 | 6,094 | 8,315 | **12.4** |
//! | squat (13 clips, 273 corrections) | 273 | (3,309, niced behind the other runs) | 170 (on all 52), 32/52 | 132/260 | 352, 128, 121 | 108 | 636 without the VAE | 2.3 without the VAE |
//!
//! Hop is a flight phase for half of every clip (floating 52-57 % before and
//! after is the jump, not a fault) and its landings press the feet 4-6 mm
//! into the floor. Its originals miss the 90 % target with this short
//! tracker (5 fail the soles, 1 skating); session 16's recipe-default tracker
//! (every clip, 1,800 s) accepted 36/36. Hop's VAE samples fail on skating
//! (58 of 64): their input skates little (0.043 m/s) and the output must not
//! skate more than its input.
//!
//! Deposit (reaching to the floor) is the hard class: with this short tracker
//! only 6 of 32 originals pass as is and 19 after fine-tuning (falls 9, soles
//! 10; sessions 14 and 17 accepted 30-32 of 32 with the recipe's default
//! tracker, every clip, 1,800 s), and its VAE samples pass 99 of 320 (31 %,
//! below the 60 % target): 186 fall, 219 fail the soles. Its 12.4 s per clip
//! is within the 15 s target but was measured while clippy, the CI run and
//! the debiasing experiments shared the cores. Squat ran on every fourth
//! clip (13) for lack of time, its VAE trained on all 52 at low priority:
//! 12/13, 130/130 and 127/130.
//!
//! ## Session 20 (2026-12-05): jog and sneak, whole classes with 10 IK edits and 10 VAE samples per clip
//!
//! Session 19's kick commands for the two locomotion classes, each pinned to
//! one core (`taskset -c 1`, `RAYON_NUM_THREADS=1`) while the other core ran
//! an eval table: `motionaug augment ../shared/data/hdm05/*C*.amc --recipe R
//! --out ik` (R = `[[ops]] op = "ik", preset = "C", copies = 10`), `vae train
//! ../shared/data/hdm05/*C*.amc --iterations 1500 --out vae_model`, `vae
//! sample vae_model --count 10N --seed 1 --out vae` (the default finish:
//! 0.05 s low-pass, root planted), `bench correction --data
//! ../shared/data/hdm05 --classes C --per-class N --tracker-clips 100
//! --tracker-budget 1800 --tracker-iterations 150 --threads 1
//! --max-iterations 15 --time-budget 300 --variant-tracker-iterations 300
//! --variants ik/*.npz vae/*.npz --out bench`:
//!
//! | class | clips | accepted | no fall | reward | residual | skating | soles | residual / m g | R_norm | skating m/s | soles flat % |
//! |---|---|---|---|---|---|---|---|---|---|---|---|
//! | jog originals | 17 | **17 (100 %)** | 17 | 17 | 17 | 17 | 17 | 0.042 | 0.901 | 0.145 -> 0.048 | 81 -> 99 |
//! | jog IK edits | 170 | **170 (100 %)** | 170 | 170 | 170 | 170 | 170 | 0.048 | 0.894 | 0.175 -> 0.048 | 75 -> 99 |
//! | jog VAE samples | 170 | **143 (84 %)** | 170 | 170 | 146 | 168 | 168 | 0.057 | 0.897 | 0.117 -> 0.022 | 31 -> 99 |
//! | sneak originals | 15 | **15 (100 %)** | 15 | 15 | 15 | 15 | 15 | 0.021 | 0.944 | 0.094 -> 0.019 | 57 -> 99 |
//! | sneak IK edits | 150 | **150 (100 %)** | 150 | 150 | 150 | 150 | 150 | 0.025 | 0.933 | 0.134 -> 0.019 | 61 -> 99 |
//! | sneak VAE samples | 150 | **97 (65 %)** | 137 | 137 | 137 | 123 | 113 | 0.037 | 0.886 | 0.103 -> 0.024 | 57 -> 87 |
//!
//! Penetration mm / floating % of the variants together: jog 0.2 -> 2.7 /
//! 18 -> 7, sneak 0.6 -> 1.3 / 4 -> 0. Wall time, everything included:
//!
//! | class | corrections | VAE training s | class tracker (iterations, s, originals as is) | second tracker (300 its) s, on | clips s | class total s | **s per clip** |
//! |---|---|---|---|---|---|---|---|
//! | jog | 357 | 581 | 140, 288, 17/17 | 761, the 193 variants failed as is | 901 | 2,551 | **7.1** |
//! | sneak | 315 | 438 | 150, 292, 14/15 | 504, 168 | 1,358 | 2,606 | **8.3** |
//! | kick (session 19) | 609 | 920 | 150, 211, 17/29 | 551, 410 | | 5,349 | 8.8 |
//!
//! The synthesis targets (IK edits >= 80 %, VAE samples >= 60 %)
//! now hold on kick, jog and sneak, and the throughput one (a class of 525
//! in <= 2 h on two cores, <= 15 s per clip) on all three with one core.
//! Jog's VAE samples went from 15/30 (session 19, the same finish) to
//! 143/170; the first 30 of today's pass 25. Two things differ: the model
//! (`vae train` on all 17 jogs, where session 19 sampled the model of `bench
//! vae`), and the second tracker, trained here on the 193 variants the class
//! tracker failed (IK edits among them) where session 19's saw only the
//! failing ones of 30 samples. Which of the two it was is not separated.
//! What rejects the rest: jog, the root force (24 of 27 rejected samples,
//! 0.10-0.18 m g); sneak, the soles (37 of 53), skating (27) and falls (13).
//!
//! ## Session 19 (2026-12-05): a whole class with 10 IK edits and 10 VAE samples per clip
//!
//! The throughput case, run end to end on **one core** (`taskset -c
//! 0`, `RAYON_NUM_THREADS=1`; the other core ran an eval table and test
//! builds): all 29 HDM05 kicks, 10 IK edits each (`motionaug augment
//! ../shared/data/hdm05/*kick*.amc --recipe R` with R = `[[ops]] op = "ik",
//! preset = "kick", copies = 10`: 6 s), a VAE trained on the 29 (`vae
//! train`, 1,500 iterations: 920 s) and 290 near samples, low-passed and
//! planted as `vae sample` now does by default (1 s), then `motionaug bench
//! correction --data ../shared/data/hdm05 --classes kick --per-class 29
//! --tracker-clips 100 --tracker-budget 1800 --tracker-iterations 150
//! --threads 1 --max-iterations 15 --time-budget 300
//! --variant-tracker-iterations 300 --variants ik/*.npz vae/*.npz` (4,422
//! s: class tracker 150 iterations, 211 s, 17/29 originals as is; the 580
//! variants judged from it, 170 pass as is; a second tracker trained 300
//! iterations (551 s) on the other 410 passes 147 of them as is; the rest
//! fine-tuned at most 15 iterations each):
//!
//! | clips | accepted | no fall | reward | residual | skating | soles | residual / m g | R_norm | skating m/s | penetration mm | floating % | soles flat % | wall s / clip |
//! |---|---|---|---|---|---|---|---|---|---|---|---|---|---|
//! | 29 originals | 25 (86 %) | 28 | 28 | 29 | 28 | 26 | 0.040 | 0.888 | 0.149 -> 0.046 | 3.1 -> 5.4 | 13 -> 1 | 80 -> 94 | 5 |
//! | 290 IK edits | **243 (84 %)** | | | | | | | | | | | | |
//! | 290 VAE samples | **226 (78 %)** | | | | | | | | | | | | |
//! | 580 variants together | 469 (81 %) | 575 | 577 | 572 | 490 | 542 | 0.038 | 0.889 | 0.154 -> 0.042 | 1.9 -> 4.5 | 10 -> 2 | 69 -> 95 | 6 |
//!
//! **609 corrections (29 x 21) in 5,349 s on one core, VAE training and
//! both trackers included: 8.8 s per clip**, so the class of 525
//! costs about 1.3 h on one core, within its 2 h on two (<= 15 s per clip).
//! Both synthesis targets are met on kick (IK edits >= 80 %, VAE samples >=
//! 60 %; session 16 with unsmoothed samples: 25/46). What rejects variants
//! now is skating (90 of 580 fail it, most against their own planted
//! input's low skating, the 0.1 m/s cap passing) and soles (38); 5 fall.
//! The originals' 86 % is below the 90 % target with this 150-iteration
//! tracker (17/29 as is; the recipe's default 1,800 s tracker took kick to
//! 29/29 in session 16). Jog's VAE samples pass 15/30 under the same
//! setting (crates/vae/README.md, session 19).
//!
//! ## Session 17 (2026-12-05): the sliding term for the clips that skate
//!
//! What rejected the last originals of grab and squat was skating alone,
//! and the sole reward's sliding term, on for every clip, had traded
//! skating rejections for soles ones (session 11). Now
//! [`CorrectConfig::skate_scale_when_skating_m_s`] (0.1 m/s by default;
//! `[correct] skate_scale_when_skating_m_s`, `--skate-scale-when-skating`)
//! switches it on only for a clip that fails on skating alone: at the first
//! judgement where skating is the one criterion failed (the warm-started
//! tracker as is, or a rollout that reaches the R_norm target during
//! fine-tuning), for the rest of that clip's training. A resumed job keeps
//! it (a note in the PPO checkpoints); `report.json` gives the scale trained
//! with (`skate_scale_m_s`), the bench table's JSON how many clips had it.
//!
//! Measured from the same trackers: `motionaug bench correction --data
//! ../shared/data/hdm05 --classes C --tracker-clips 100 --tracker-budget
//! 1800 --per-class 100 --time-budget 300 --threads 1 --out DIR
//! [--skate-scale-when-skating 0|0.1]`, the tracker folder copied into each
//! arm's DIR, one process per core while builds, tests and the other
//! class's arms ran. Arms: off; on whenever skating failed (a first version);
//! on when skating alone failed (the default):
//!
//! | class | arm | accepted | as is | fine-tuned (term on) | rejected by | residual / m g | R_norm | skating m/s | soles flat % | clips s |
//! |---|---|---|---|---|---|---|---|---|---|---|
//! | grab | off | 27/29 (93 %) | 23 | 6 (0) | skating: tr 023 0.134, tr 024 0.197 m/s | 0.013 | 0.955 | 0.111 -> 0.040 | 70 -> 99 | 650 |
//! | grab | skating failed | 29/29 | 23 | 6 (5) | | 0.013 | 0.954 | 0.111 -> 0.035 | 70 -> 99 | 340 |
//! | grab | **skating alone** | **29/29** | 23 | 6 (5) | | 0.013 | 0.955 | 0.111 -> 0.036 | 70 -> 99 | 316 |
//! | squat | off | 48/52 (92 %) | 45 | 7 (0) | skating: bd 011, bd 012, bk 015, bk 016 (0.138-0.192 m/s) | 0.018 | 0.933 | 0.126 -> 0.051 | 45 -> 99 | 1,266 |
//! | squat | skating failed | 52/52 | 45 | 7 (6) | | 0.018 | 0.932 | 0.126 -> 0.045 | 45 -> 99 | 258 |
//! | squat | **skating alone** | **52/52** | 45 | 7 (6) | | 0.018 | 0.932 | 0.126 -> 0.046 | 45 -> 99 | 251 |
//! | deposit | off | 32/32 | 25 | 7 (0) | | 0.022 | 0.937 | 0.093 -> 0.022 | 83 -> 98 | 455 |
//! | deposit | skating failed | 31/32 | 25 | 7 (1) | dg 018 falls | 0.022 | 0.926 | 0.093 -> 0.021 | 83 -> 98 | 478 |
//! | deposit | **skating alone** | **32/32** | 25 | 7 (0) | | 0.022 | 0.937 | 0.093 -> 0.022 | 83 -> 98 | 226 |
//!
//! The trackers: grab 855 iterations (kept 845), squat 845 (815), deposit
//! 831, each in its 1,800 s on a shared core (session 14's deposit tracker
//! had 1,366-1,642). Every clip the default switched on for was accepted, in
//! 3-175 s, where the arm without it spent its 300 s on each rejected one;
//! the soles held on all of them. Training stops at the first rollout that
//! passes, so their output skating sits just under the limit (0.069-0.100
//! m/s, inputs 0.069-0.622). The first version also switched it on where
//! skating failed beside other criteria: it cost deposit dg 018 (fell as
//! is; with the term it fell again after 299 s, without it accepted), and,
//! on jog's synthesised clips, an IK edit (then root force 0.110 m g) and a
//! VAE sample (soles 0.81) that pass without it. Deposit's 0 of 7 switched
//! on under the default makes it the off arm again (its clips' seconds
//! differ by the machine's load only). With this, every HDM05 class's
//! originals are accepted under the criteria with 300 s per clip: kick
//! 29/29, jog 17/17, sneak 15/15, hop 36/36 (sessions 15-16), grab 29/29,
//! squat 52/52, deposit 32/32.
//!
//! **A class with its variants.** `motionaug augment` on the 17 jogs, recipe
//! `[[ops]] op = "ik", preset = "jog", copies = 2`, `[vae] copies = 34`,
//! `[correct] policy = "class", time_budget_s = 300, max_iterations = 15,
//! tracker_budget_s = 1800, keep_rejected = true, variant_tracker_iterations
//! = 300` and the three settings of the term (the same 68 inputs, trackers
//! and second tracker; the corrections redone):
//!
//! | jog variants | IK edits accepted | VAE samples accepted | VAE falls | term on (IK, VAE) | training s (IK, VAE) |
//! |---|---|---|---|---|---|
//! | off | 33/34 | 5/34 | 20 | 0, 0 | 75, 952 |
//! | on whenever skating failed | 32/34 | 4/34 | 21 | 1, 16 | 48, 770 |
//! | **on when skating alone failed** | **33/34** | **5/34** | 20 | 0, 0 | 45, 756 |
//!
//! Under the default the term never switched on for a jog variant: the same
//! verdicts as without it (the seconds differ by the machine's load).
//!
//! The whole class (17 originals, 34 IK edits, 34 VAE samples) through the
//! pipeline on one core while the other built and tested: 33 min (VAE ~7
//! min, tracker 194 s and 115 iterations passing all 17 originals as is, the
//! class tracker passing 28 of the 68 new clips as is, the second tracker
//! 300 iterations on the other 40 in 543 s, the corrections ~14 min). VAE
//! acceptance (12-15 %) stays far from the 60 %: 20 of 34 fall (the
//! decoder's near samples, session 16).
//!
//! ## Session 16 (2026-12-05): every class's originals from a tracker on every clip; the second tracker in the pipeline
//!
//! **Originals.** `motionaug bench correction --data ../shared/data/hdm05
//! --classes C --tracker-clips 100 --tracker-budget 1800 --per-class 100
//! --time-budget 300 --threads 1 --out DIR`, one process pinned to one core
//! (`taskset`, `RAYON_NUM_THREADS=1`) while the other core ran an eval
//! table, VAE training and builds; the classes session 11 had measured with
//! 10-clip trackers only:
//!
//! | class | clips | accepted | tracker: iterations, s, passed as is | residual / m g | R_norm | skating m/s | penetration mm | floating % | soles flat % | clips s | class total s |
//! |---|---|---|---|---|---|---|---|---|---|---|---|
//! | kick | 29 | **29 (100 %)** | 1,210, 1,799, 26/29 | 0.023 | 0.923 | 0.149 -> 0.033 | 3.1 -> 5.8 | 13 -> 0 | 80 -> 99 | 32 | 1,831 |
//! | jog | 17 | **17 (100 %)** | 140, 205, 17/17 (stopped: all pass) | 0.042 | 0.901 | 0.145 -> 0.048 | 0.2 -> 4.4 | 27 -> 15 | 81 -> 99 | 0 | 205 |
//! | sneak | 15 | **15 (100 %)** | 170, 235, 15/15 (stopped: all pass) | 0.018 | 0.949 | 0.094 -> 0.018 | 0.3 -> 2.3 | 8 -> 0 | 57 -> 99 | 0 | 236 |
//! | grab | 29 | 25 (86 %) | 1,142, 1,799, 22/29 | 0.014 | 0.951 | 0.111 -> 0.050 | 1.7 -> 3.0 | 5 -> 1 | 70 -> 99 | 1,325 | 3,125 |
//! | grab's 4 rejected, fine-tuned with the sliding term | 4 | **4** | the same tracker | 0.014 | 0.954 | 0.169 -> 0.091 | 1.3 -> 3.9 | 15 -> 0 | 32 -> 100 | 648 | |
//!
//! Grab's 4 rejected clips (bk 005, dg 013, tr 023, tr 024) failed on
//! skating alone (0.139-0.274 m/s after 300 s of fine-tuning; inputs
//! 0.077-0.314), with residual 0.009-0.014 m g and R_norm >= 0.95. Fine-tuned
//! again from the same tracker with the sole reward's sliding term
//! (`bench correction ... --per-class 0 --skate-scale 0.1 --variants <the 4
//! AMC files>`, the test suite running on both cores) all 4 pass in 67-222
//! s: grab **29/29** with the sliding term for the clips that skate. (On
//! squat, session 11, the same term traded skating rejections for soles
//! ones; a sliding term only for clips rejected on skating is the next
//! thing to build.) With sessions 14-15 (deposit 30/32, squat 48/52 with
//! 300 s per clip, hop 36/36, same setting) every HDM05 class is at or
//! above the 90 % of originals, grab only with the sliding term.
//!
//! **The second tracker in the pipeline.** `[correct]
//! variant_tracker_iterations = N` (with `policy = "class"`) plans one
//! `variant_tracker` job per class with new clips: it waits for the class
//! tracker and for every job that made the class's clips, judges each new
//! clip with the class tracker as is (`judged/class.json`), and trains a
//! second tracker from the class tracker, at its residual gains, on the
//! clips it fails (at most N PPO iterations within `tracker_budget_s`); a
//! new clip's `correct` job starts from the second tracker when the class
//! tracker failed it, else from the class tracker. The same stage
//! (`pipeline::stages::train_variant_tracker`) serves `motionaug augment`,
//! the service's workers (judgement, report and checkpoint shared through
//! the coordinator like the class tracker's), `eval table
//! --variant-tracker-iterations` and `bench correction --variants`. Its
//! effect, 300 iterations: jog VAE samples accepted 2/34 -> 8/34 (session
//! 15's bench); the kick eval fold (bd, seed 0; `eval` crate README) IK
//! edits 33/46 -> 43/46 and VAE samples 11/46 -> 25/46, for 935 s of
//! second tracker on a loaded core, and the full method's prediction error
//! 0.10-0.28 rad lower. Off by default until more classes are measured.
//!
//! **Why the VAE samples fall.** Most of them do not move: near codes drawn
//! between the paper's two training clips decode to nearly frozen mid-jog
//! poses (pose speed 0.11-0.29 m/s where captured jogs move 0.59-0.87; the
//! `vae` crate's README), and a frozen mid-stride pose cannot be balanced.
//! Drawn near one clip they move like jogs but their feet slide twice as
//! much as the captures', and none of 23 was accepted either (19 falls,
//! the rest 0.15-0.28 m g of root force). VAE acceptance is limited by the
//! decoder, not by the tracker or the criteria.
//!
//! ## Session 15 (2026-12-04): squat and hop from a tracker on every clip; a class with its variants
//!
//! **Originals.** `motionaug bench correction --data ../shared/data/hdm05
//! --classes squat,hop --tracker-clips 100 --tracker-budget 1800 --per-class
//! 100 --max-iterations 15 --threads 1 --out DIR` (one process on one core;
//! the other core ran the jog runs below and builds), the setting that gave
//! deposit 30 of 32 in session 14:
//!
//! | class | clips | accepted | tracker: iterations (kept), s, passed as is | residual / m g | R_norm | skating m/s | penetration mm | floating % | soles flat % | clips s | class total s |
//! |---|---|---|---|---|---|---|---|---|---|---|---|
//! | squat | 52 | 46 (88 %) | 1,100 (1,090), 1,799, 44/52 | 0.018 | 0.932 | 0.126 -> 0.046 | 2.4 -> 2.2 | 14 -> 2 | 45 -> 98 | 129 | 1,928 |
//! | squat, 300 s per clip | 52 | **48 (92 %)** | the same tracker | 0.017 | 0.934 | 0.126 -> 0.046 | 2.4 -> 2.3 | 14 -> 1 | 45 -> 99 | 1,328 | 3,127 |
//! | hop | 36 | **36 (100 %)** | 980, 1,360, 36/36 (stopped: all pass) | 0.033 | 0.904 | 0.199 -> 0.036 | 0.9 -> 6.6 | 53 -> 49 | 91 -> 100 | 0 (all pass as is) | 1,360 + 36 rollouts |
//!
//! Session 11 (a 10-clip tracker of 150 iterations): squat 41 of 52, hop 30
//! of 36. The second squat row is the per-clip budget: the same
//! command with `--time-budget 300` and no `--max-iterations`, the tracker
//! and the 46 accepted clips reused, the 6 rejected ones fine-tuned again
//! from the tracker for up to 300 s each: 2 more accepted (bd 006 after 44
//! s, dg 026). The 4 still rejected are bd squats whose *captured* feet
//! slide 0.26-0.44 m/s; the simulated ones still slide 0.13-0.19 m/s after
//! 300 s (0.11-0.17 after 15 iterations: longer training does not lower it,
//! the reward has no sliding term by default). Residual force, falls and
//! soles pass on every squat. Hop's mean penetration rises to 6.6 mm (feet
//! landing from a hop sink into the contact before the solver pushes them
//! out); it is not an acceptance criterion. "clips s" is the clips'
//! training time (a clip passed as is costs one rollout, about a second).
//!
//! **A class with its variants, through the pipeline.** `motionaug augment
//! ../shared/data/hdm05/HDM_*_jog*.amc --recipe R --out OUT` with R: `[[ops]]
//! op = "ik", preset = "jog", copies = 2`; `[vae] copies = 34` (1,500
//! iterations); `[correct] policy = "class", time_budget_s = 300,
//! max_iterations = 15, tracker_budget_s = 1800, keep_rejected = true`. One
//! core (`taskset`), the other running the squat/hop bench: **25 min 36 s**
//! for 17 jogs, 34 IK edits and 34 VAE samples: VAE ~7 min, tracker 205 s
//! (145 iterations, all 17 originals pass), IK edits **34 of 34** accepted
//! (30 as is, 4 after 3-10 iterations; 32 s of training in all), VAE samples
//! **2 of 34** (873 s; 27 fall within the first second, R_norm 0.2-0.6).
//! At these rates the class of 525 (25 clips, 10 IK edits and 10
//! VAE samples each) costs tracker + VAE + 250 x ~2 s + 250 x ~26 s: with
//! jog's tracker (205 s) about 2.1 h on one core, 1.1 h on two (tracker and
//! VAE side by side, the corrections split), 1.5 h with a tracker that uses
//! its whole 1,800 s; within the 2 h target. The VAE samples' acceptance
//! (6 %) is far from its 60 % target.
//!
//! **A second tracker for the variants the class tracker fails** (`bench
//! correction --variants CLIP... --variant-tracker-iterations 300`, the same
//! tracker and the same 68 synthesised clips, written by the recipe without
//! `[correct]`; the variants' inputs and as-is verdicts match the pipeline
//! run's exactly). The class tracker passes 30 of 68 as is; a second tracker,
//! warm-started from it at its residual gains, trains 300 iterations (414 s)
//! on the other 38; each of those is then judged from the second tracker and
//! fine-tuned 15 iterations when it fails:
//!
//! | variants start from | IK edits accepted | VAE samples accepted | VAE falls | clip s | tracker s |
//! |---|---|---|---|---|---|
//! | the class tracker (the pipeline today) | 34/34 | 2/34 (6 %) | 27 | 905 | 0 |
//! | a second tracker trained on all 68 (every variant starts from it) | 34/34 (all as is) | 5/34 (15 %) | 12 | 610 | 584 |
//! | **a second tracker trained on the 38 the class tracker fails** | 34/34 (all as is) | **8/34 (24 %)** | 6 | 572 | 414 |
//!
//! Four times the VAE acceptance for about the same time (986 s against
//! 905 s); falls drop from 27 to 6, and what rejects the rest is now
//! residual force above 0.1 m g (20), skating above the input's (18) and
//! soles (17): samples the character can follow only with help. Training
//! the second tracker on the clips the first one already passes spends its
//! iterations where nothing is to be gained (its 300 iterations took 584 s
//! against 414 s, on a busier machine). The pipeline does not have
//! the second tracker yet: it needs a job per class that waits for every
//! synthesised clip of the class, between the tracker and the corrections.
//!
//! ## Session 14 (2026-12-04): deposit from a tracker on every clip, and the best judged tracker kept
//!
//! `motionaug bench correction --data ../shared/data/hdm05 --classes deposit
//! --tracker-clips 32 --tracker-budget 3600 --per-class 100 --max-iterations
//! 15 --threads 1 --out DIR` (one core; the other ran an eval table): the
//! tracker trained on all 32 deposits for 3600 s (2,693 PPO iterations),
//! judged every 5 iterations. Clips accepted as is, per 300 iterations
//! (min / max / mean of the judgements):
//!
//! | iterations | 0-300 | 300-600 | 600-900 | 900-1200 | 1200-1500 | 1500-1800 | 1800-2100 | 2100-2400 | 2400-2700 |
//! |---|---|---|---|---|---|---|---|---|---|
//! | accepted / 32 | 0-15 (6.6) | 14-24 (20.9) | 20-28 (24.0) | 22-29 (24.8) | 21-29 (25.5) | 21-28 (25.4) | 23-29 (25.7) | 21-28 (24.7) | 22-29 (26.3) |
//!
//! From iteration ~900 the count swings between 21 and 29 from one
//! judgement to the next. This run's binary kept the last tracker, which
//! passed 22 clips as is; the best judged one (iteration 1,170, and again at
//! 1,480, 1,845, 2,400, 2,440) passed 29 of 32 (91 %). From the last
//! tracker, after fine-tuning the 10 clips it failed (15 PPO iterations
//! each, 116 s for the class): **28 of 32 accepted** (88 %; session 11: 20
//! of 32 from a 10-clip, 150-iteration tracker, 25 at 300). Rejected: 2
//! falls, 4 with the output skating above the input's (e.g. 0.069 against
//! 0.067 m/s), 1 soles. Residual force 0.021 m g, skating 0.093 -> 0.035
//! m/s, soles flat 83 -> 96 % of planted frames; 3,717 s for the class on
//! one core.
//!
//! The same command keeping the best judged tracker instead, with the
//! default budget of a recipe's tracker (`--tracker-budget 1800`; 1,642
//! iterations): the judgements follow the first run's exactly (same seed)
//! up to the budget, the last passes 25 of 32 as is, the best (iteration
//! 1,170) 29. After fine-tuning the 3 it fails: **30 of 32 deposits
//! accepted (94 %)**; rejected: 1 fall, 1 soles (and it skates). Residual
//! force 0.021 m g, R_norm 0.919, skating 0.093 -> 0.021 m/s, penetration
//! 2.4 -> 3.5 mm, floating 2 -> 1 %, soles flat 83 -> 98 %; the clips 38 s
//! in all, 1,838 s for the class on one core (tracker 1,800 s).
//!
//! But the best judged tracker is not the one to keep for the variants: in
//! the kick table (fold bd, `eval table --correct-policy class`, 150
//! tracker iterations) the best judgement (9 of 23 originals as is, at
//! iteration 95) against the last (8, at 150) gave, after fine-tuning, 17
//! of 23 originals and 26 of 46 IK edits against 19 and 36 (3 of 46 VAE
//! samples against 8 in session 13). One clip more on the training clips
//! bought 55 fewer iterations of training. The rule kept since
//! ([`class`]): the latest judgement within 5 % of the clips (at least one)
//! of the best; on kick that is the last. Deposit with it, the same
//! command (`--tracker-budget 1800`, 1,366 iterations: the machine was
//! busier): the last judgement (27 of 32 as is) is within 2 of the best
//! (29) and kept; after fine-tuning **30 of 32 accepted (94 %)**, 2 falls;
//! residual 0.022 m g, skating 0.093 -> 0.025 m/s, soles flat 83 -> 97 %,
//! 1,846 s for the class on one core.
//!
//! ## Session 11 (2026-12-03): a sliding term, planted references, throughput one class per core
//!
//! Every run: `motionaug bench correction --data ../shared/data/hdm05
//! --classes C --tracker-clips 10 --tracker-iterations 150 --per-class 100
//! --max-iterations 15 --threads 1 --out DIR` (one tracker per class, every
//! clip judged from it and fine-tuned 15 PPO iterations at most when it
//! fails), two such processes side by side, one per core.
//!
//! **Sliding term of the sole reward** (`--skate-scale 0.1` against the
//! default 0, squat, the two arms side by side while the test suite also ran):
//!
//! | skate scale | accepted / 52 | no fall | reward | residual | skating | soles | residual / m g | R_norm | skating m/s | soles flat % | wall s / clip | wall s total |
//! |---|---|---|---|---|---|---|---|---|---|---|---|---|
//! | 0 (default) | 41 (79 %) | 51 | 51 | 51 | 43 | 48 | 0.031 | 0.909 | 0.126 -> 0.065 | 45 -> 96 | 18 | 2045 |
//! | 0.1 m/s | 42 (81 %) | 52 | 52 | 52 | 48 | 44 | 0.032 | 0.915 | 0.126 -> 0.049 | 45 -> 92 | 15 | 1876 |
//!
//! The term trades skating rejections (9 -> 4) for soles rejections (4 ->
//! 8): planted feet that may not slide roll onto their toes instead. One
//! clip more is accepted; the default stays off until it is measured on the
//! other classes.
//!
//! **Planted reference** (`physics::Config::plant_reference`, the root
//! re-integrated from the capture's planted feet before imitation; acceptance
//! still against the clip as given): hop 30 of 36 accepted against 31 with
//! the raw reference (session 9), squat 17 of its first 24 clips against 19
//! (run stopped there). The bd squats whose inputs skate 0.28-0.44 m/s still
//! skate 0.11-0.21 m/s after correction either way: the skating is not the
//! root force dragging the body along a drifting root. Off by default.
//!
//! **Throughput, one class per core.** Two `bench correction` processes of
//! one rollout thread each, side by side on the 2 cores and nothing else
//! running (kick + deposit in one, jog + grab + sneak in the other; default
//! settings, `--threads 1`); squat from the sliding-term run above (the test
//! suite shared the cores for its first 10 minutes). Wall seconds of one
//! process, that is of one core:
//!
//! | class | clips | accepted | tracker: iterations, s, passed as is | clips: s in all, s per clip | class total s | s per clip incl. tracker | residual / m g | skating m/s | soles flat % |
//! |---|---|---|---|---|---|---|---|---|---|
//! | kick | 29 | 26 (90 %) | 150, 680, 9/10 | 544, 19 | 1224 | 42 | 0.042 | 0.149 -> 0.044 | 80 -> 96 |
//! | deposit | 32 | 20 (63 %) | 150, 668, 4/10 | 1050, 33 | 1718 | 54 | 0.040 | 0.093 -> 0.030 | 83 -> 86 |
//! | jog | 17 | 17 (100 %) | 95, 445, 10/10 | 40, 2 | 485 | 29 | 0.054 | 0.145 -> 0.050 | 81 -> 99 |
//! | grab | 29 | 26 (90 %) | 150, 615, 9/10 | 372, 13 | 987 | 34 | 0.019 | 0.111 -> 0.036 | 70 -> 92 |
//! | sneak | 15 | 15 (100 %) | 125, 538, 10/10 | 72, 5 | 610 | 41 | 0.024 | 0.094 -> 0.020 | 57 -> 98 |
//! | squat | 52 | 41 (79 %) | 150, 1080, 5/10 | 961, 18 | 2045 | 39 | 0.031 | 0.126 -> 0.065 | 45 -> 96 |
//! | hop (planted reference) | 36 | 30 (83 %) | 110, 537, 10/10 | 405, 11 | 945 | 26 | 0.055 | 0.199 -> 0.046 | 91 -> 91 |
//!
//! A clip the tracker passes as is costs about a second (one rollout); one
//! it does not costs its 15 fine-tuning iterations, 50-70 s on one core.
//! The tracker (7-18 min on one core) is paid once per class. For the
//! issue's class of 525 corrections on two cores (corrections split over two
//! processes), tracker + 525 x (s per clip) / 2, at the originals' per-clip
//! cost: jog 0.3 h, sneak 0.5 h, grab 1.1 h, hop 0.9 h, squat 1.6 h, kick
//! 1.6 h, deposit 2.6 h; within 2 h (<= 15 s of machine time per clip)
//! except deposit. Variants are judged and fine-tuned the same way but
//! fail as is more often than originals, so they cost more per clip than
//! this; their per-clip cost under this setting has not been measured.
//! Deposit is limited by its tracker (4 of 10 training clips pass after 150
//! iterations): 12 of 32 clips rejected, 7 by falls and 13 with soles off
//! the floor (82-89 % of planted frames flat). The same tracker resumed to
//! 300 iterations (`--tracker-iterations 300`, its 150-iteration checkpoint
//! resumed, one core while a build used the other; 1253 s in all) passes 6
//! of its 10 clips at 300 (8 at 295), and
//! then 25 of 32 deposits are accepted (78 %; 6 falls), 20 s per clip
//! (641 s for the 32), residual 0.033 m g, skating 0.093 -> 0.042 m/s,
//! soles flat 83 -> 89 %: the class of 525 at about 1.8 h. A longer tracker
//! is cheap where the class is large; the default budget is unchanged until
//! the other classes are measured with it.
//!
//! ## Every clip of a class from one tracker (2026-12-02, session 9)
//!
//! `motionaug bench correction --data ../shared/data/hdm05 --classes
//! kick,jog,hop,squat,sneak,deposit,grab --tracker-clips 10
//! --tracker-iterations 150 --per-class 100 --max-iterations 15 --out DIR`:
//! per class, one tracker trained on 10 of its clips (spread over the five
//! actors), then *every* clip of the class judged from it as is and, when it
//! does not pass, fine-tuned for 15 PPO iterations at most. Defaults
//! otherwise (the criteria of [`acceptance`] with "planted" = standing
//! still, physics at 1/60 s with 2 substeps of 5 passes, candle on one
//! thread). Wall times were measured while the machine ran other work (load
//! average 9-11 on 2 cores: a VAE study, a DMGNN training, builds), so they
//! are upper bounds, not throughput on a quiet machine:
//!
//! | class | clips | accepted | no fall | reward | residual | skating | soles | residual / m g | R_norm | skating m/s | penetration mm | floating % | soles flat % | wall s / clip | wall s total | tracker: iterations, s, accepted as is |
//! |---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|
//! | kick | 29 | 26 (90 %) | 28 | 28 | 28 | 29 | 26 | 0.041 | 0.892 | 0.149 -> 0.045 | 3.1 -> 4.8 | 13 -> 1 | 80 -> 94 | 20 | 569 | 150, 320 s, 8/10 |
//! | jog | 17 | 17 (100 %) | 17 | 17 | 17 | 17 | 17 | 0.058 | 0.882 | 0.145 -> 0.049 | 0.2 -> 3.2 | 27 -> 19 | 81 -> 100 | 6 | 101 | 95 (all 10 passed), 736 s |
//! | hop | 36 | 31 (86 %) | 36 | 36 | 36 | 33 | 32 | 0.054 | 0.849 | 0.199 -> 0.040 | 0.9 -> 5.5 | 53 -> 50 | 91 -> 94 | 17 | 629 | 150, 604 s, 5/10 |
//! | squat | 52 | 39 (75 %) | 51 | 51 | 52 | 43 | 44 | 0.033 | 0.902 | 0.126 -> 0.061 | 2.4 -> 1.3 | 14 -> 2 | 45 -> 94 | 14 | 725 | 150, 411 s, 4/10 |
//! | sneak | 15 | 15 (100 %) | 15 | 15 | 15 | 15 | 15 | 0.025 | 0.931 | 0.094 -> 0.020 | 0.3 -> 1.7 | 8 -> 1 | 57 -> 98 | 1 | 19 | 110 (all 10 passed), 295 s |
//! | deposit | 32 | 19 (59 %) | 23 | 24 | 32 | 32 | 22 | 0.036 | 0.801 | 0.093 -> 0.031 | 2.4 -> 4.2 | 2 -> 1 | 83 -> 88 | 15 | 467 | 150, 349 s, 3/10 |
//! | grab | 29 | 26 (90 %) | 28 | 28 | 29 | 27 | 26 | 0.020 | 0.937 | 0.111 -> 0.036 | 1.7 -> 2.3 | 5 -> 2 | 70 -> 93 | 5 | 154 | 150, 241 s, 8/10 |
//!
//! All seven classes, 210 clips: 163 accepted (78 %), 4117 s for the run.
//! Deposit (bending to the floor) falls in 9 of 32 clips: its tracker passed
//! 3 of its 10 clips after 150 iterations.
//!
//! Variants, through the pipeline (`motionaug augment
//! ../shared/data/hdm05/HDM_*_kickLFront1Reps_*.amc --recipe R`, R: one
//! `ik` kick copy per clip, `[vae] copies = 10`, `[correct] policy =
//! "class"`, `tracker_iterations = 150`, `max_iterations = 15`): 20 of 29
//! IK variants accepted (69 %, target 80 %), 0 of 10 VAE samples (6 fall, 3
//! need more root force than 0.1 m g, 1 skates; target 60 %). The VAE's
//! samples are what limits the last: see issue 17's work on their skating.
//!
//! Session 10, VAE samples with foot terms, hip-height scaling and planted
//! roots (`vae` crate README; recipe `[vae] copies = 10, iterations = 1500`,
//! `[correct] policy = "class"`, `time_budget_s = 300`, `tracker_iterations =
//! 150`, `max_iterations = 15`, `keep_rejected = true`; 31 min in all, two
//! heavy processes on the 2 cores: VAE ~20 min, tracker 234 s, the 10
//! corrections 0-23 s each): 5 of 10 accepted (target 60 %). Rejected: 1 fall
//! (with reward, root force, skating and soles failing too), 2 on soles (72 %
//! and 79 % of planted frames flat, one also root force 0.127), 2 only on
//! skating against their own input: planting brought the inputs' skating to
//! 0.017 and 0.024 m/s and the simulated feet slide 0.024 and 0.043 m/s, under
//! the 0.1 cap but above the input, which the criterion forbids. Inputs now
//! skate 0.017-0.148 m/s (before planting and the foot terms: ~0.44).
//!
//! The same recipe on jog (17 clips; 19 min in all, VAE ~12 min): 0 of 10
//! accepted, every sample falls (R_norm 0.22-0.64, root force 0.10-0.24 m g)
//! although the class tracker accepts 17 of 17 jog originals (table above).
//! The decoded jogs are kinematically tidier (skating 0.016-0.36 m/s before
//! correction) but not dynamically trackable: in `motionaug bench vae` (bd
//! held out) jog samples' frames float more than the captures' (42-52 % vs
//! 22 %) and reconstructions are 0.10-0.13 rad from the captured poses. What limits VAE jog acceptance is the
//! VAE's pose quality, not the tracker.
//!
//! Class totals (tracker + every clip): kick 889 s (31 s per clip), jog
//! 837 s (49 s; its tracker began under the slower candle threading), hop
//! 1233 s (34 s), squat 1136 s (22 s), sneak 314 s (21 s), deposit 816 s
//! (26 s), grab 395 s (14 s). Before this session the same kick tracker (150
//! iterations) passed 2-3 of its 10 clips and 1 of 4 held-out kicks.
//! What rejects the rest: a few planted frames off the sole (hop clips with
//! 3-18 planted foot frames in all, so one frame is 6-30 %), skating above
//! the input's (hop 0.10-0.18 m/s; squat 0.12-0.25 m/s, where the input's
//! feet hardly move), one kick that falls (tr 029). The squat's soles pass
//! in 44 of 52 clips although only 6 of its 52 captured inputs do (see the
//! next section): the policy keeps its heels down where the squatters rose
//! onto the balls of their feet.
//!
//! ## What "planted" means, and what the capture itself scores
//!
//! A planted foot is one *standing still*: touching the floor with its heel
//! and its toe both slower than 0.2 m/s (3D). Until 2026-12-02 it was the
//! sole's midpoint moving slower than 0.2 m/s horizontally, which counted a
//! foot rolling over its heel or onto its toes (one end moving fast, the
//! midpoint barely) as planted and not flat. A foot standing on its heel
//! with the toes up, or on its toes with the heel up, moves neither end and
//! is judged as before. `motionaug bench soles --data ../shared/data/hdm05`
//! scores the criterion (heel and toe within 2 cm in >= 90 % of planted
//! frames) on the captured clips themselves, with the character's sole
//! points (deterministic, 1 s for 210 clips); inputs passing / clips, mean
//! flat fraction, before -> after the change:
//!
//! | class | clips | inputs passing | mean flat | planted foot frames |
//! |---|---|---|---|---|
//! | depositFloorR | 32 | 16 -> 18 | 0.77 -> 0.83 | 3882 -> 3455 |
//! | grabHighR | 29 | 11 -> 12 | 0.67 -> 0.70 | 2471 -> 2281 |
//! | hopBothLegs1hops | 36 | 21 -> 30 | 0.82 -> 0.91 | 433 -> 128 |
//! | jogLeftCircle4StepsRstart | 17 | 0 -> 6 | 0.65 -> 0.81 | 560 -> 312 |
//! | kickLFront1Reps | 29 | 4 -> 12 | 0.70 -> 0.80 | 1406 -> 1046 |
//! | sneak2StepsLStart | 15 | 0 -> 3 | 0.47 -> 0.57 | 871 -> 662 |
//! | squat1Reps | 52 | 0 -> 6 | 0.29 -> 0.45 | 2918 -> 1653 |
//!
//! What still fails is in the capture: the squatters rise onto the balls of
//! their feet (bd squat 001: the ankle joint rises 0.107 -> 0.144 m while the
//! toe joint stays at 0.04-0.05 m, the heel of the foot box 6 cm up for
//! several frames), sneakers walk on their toes, grabbers reach up on tiptoe.
//! A faithful imitation of those frames stands on the front edge of the
//! one-box foot, which the criterion (heel *and* toe down) rejects; only a
//! policy that keeps its heels down where the capture lifts them passes.
//! That is what bounds acceptance of the originals of these classes under
//! the definition; the limit is kept.
//!
//! ## A tracker per class, measured (2026-12-02)
//!
//! `motionaug bench correction --data ../shared/data/hdm05 --classes kick
//! --tracker-clips 10 --tracker-iterations 150 --held-out --per-class 4
//! --max-iterations 30 --out DIR`: one tracker on 10 kicks of all five actors
//! (150 PPO iterations, 614k samples), then 4 other kicks fine-tuned from it.
//! The tracker does every training clip without a fall and with a residual
//! force of 0.021-0.054 m g (all pass that criterion), mean R_norm rising
//! 0.84 -> 0.91 over training; 2-3 of the 10 pass every criterion as is.
//! What rejects the rest is the soles (78-89 % of planted frames flat, one
//! clip 30 %) and foot skating above the input's. Fine-tuned (30 iterations
//! at most), 1 of the 4 held-out kicks is accepted, the others by the soles
//! (79 % on average). The machine was shared with three builds: 50 min of
//! wall time for 15 min of CPU time, so wall times are not throughput.
//!
//! What limits the soles criterion is the capture itself: the same test on
//! the *input's* feet (`report.json`: `soles_flat_before`, the reference's
//! heel and toe with the character's soles, planted = within 2 cm of the
//! floor and slower than 0.2 m/s) gives 0.71 / 0.58 / 0.68 / 0.73 / 0.62 for
//! bd deposit / grab / jog / kick / sneak 001, 0.24-0.95 over 15 clips of
//! five classes: captured people rise onto their toes and roll over their
//! heels while a foot is planted, so "heel and toe within 2 cm in >= 90 % of
//! planted frames" is stricter than the motion being imitated.
//!
//! ## Honest acceptance, measured (2026-12-02)
//!
//! `motionaug bench correction --data ../shared/data/hdm05 --classes
//! kick,jog,sneak,grab,deposit,hop,squat --per-class 2 --max-iterations 10
//! --out DIR [--rest-feet]` (the first and a middle clip of each class, 10 PPO
//! iterations = 41k samples, ~28 s per clip on this 2-core machine while other
//! builds ran). No clip of 14 is accepted under the criteria of
//! [`acceptance`] (none was rejected before them but the falls); per class,
//! planted foot frames on the sole with the rest-pose feet -> with the feet
//! built in the standing foot's frame (the default now):
//! kick 6 -> 50 %, jog 30 -> 52 %, sneak 9 -> 27 %, grab 48 -> 82 %,
//! deposit 44 -> 54 %, hop 5 -> 69 %, squat 21 -> 46 %; residual force
//! 0.04-0.20 m g. With 60 iterations (~190 s per clip) on bd kick / jog /
//! squat 001: residual 0.108 / 0.097 / 0.058 m g, and 0.044 / 0.075 / 0.024
//! with the residual schedule ([`ResidualSchedule`], now the default); soles
//! flat 63 / 62 / 46 % remains what rejects them.
//!
//! With the sole reward added (`physics::Config::sole_reward_weight` 0.2; the
//! defaults now: standing-frame feet, residual schedule, sole reward), 60
//! iterations at most, `--per-class 2` (the bd 001 clip and a middle clip of
//! dg / bk), 5 of 14 are accepted, one per class but jog and grab:
//!
//! | class | clips | accepted | no fall | reward | residual | skating | soles | residual / m g | R_norm | skating m/s | soles flat % | wall s / clip |
//! |---|---|---|---|---|---|---|---|---|---|---|---|---|
//! | kick | 2 | 1 | 2 | 2 | 1 | 1 | 1 | 0.096 | 0.802 | 0.137 -> 0.193 | 63 | 229 |
//! | jog | 2 | 0 | 1 | 1 | 1 | 1 | 0 | 0.141 | 0.631 | 0.126 -> 0.223 | 56 | 252 |
//! | sneak | 2 | 1 | 2 | 2 | 2 | 2 | 1 | 0.063 | 0.907 | 0.118 -> 0.049 | 79 | 180 |
//! | grab | 2 | 0 | 2 | 2 | 2 | 0 | 2 | 0.015 | 0.980 | 0.014 -> 0.035 | 100 | 153 |
//! | deposit | 2 | 1 | 2 | 2 | 2 | 2 | 1 | 0.037 | 0.907 | 0.135 -> 0.069 | 73 | 137 |
//! | hop | 2 | 1 | 2 | 2 | 2 | 2 | 1 | 0.069 | 0.848 | 0.182 -> 0.052 | 86 | 58 |
//! | squat | 2 | 1 | 2 | 2 | 2 | 2 | 1 | 0.055 | 0.871 | 0.101 -> 0.041 | 58 | 80 |
//!
//! (criterion columns: clips that passed it). What rejects the rest: feet
//! not on their soles in 24-80 % of planted frames, the dg jog falling, and
//! grab skating 0.035 m/s where its clean input skates 0.008-0.020. The
//! earlier tables below predate the criteria (they judged mean reward only).
//!
//! Measured on 2026-11-22 (2-core machine, release build, defaults: [256, 256]
//! nets, 8 envs, 2 threads, 4096 samples per iteration; `motionaug correct
//! CLIP --skeleton examples/data/HDM_bd.asf --out DIR --time-budget 150
//! --target-r-norm 0.99`):
//!
//! | clip | R_norm action 0 -> trained | residual force / m g | samples, wall |
//! |---|---|---|---|
//! | HDM05 bd kick 001 | 0.871 -> 0.923 | 0.087 | 344k, 148 s |
//! | IK kick (ik_kick.toml, seed 1, copy 0) | 0.869 -> 0.910 | 0.097 | 324k, 149 s |
//! | HDM05 bd jog 001 (target 0.8) | 0.599 (falls) -> 0.904 | 0.110 | 86k, 37 s |
//!
//! Measured again on 2026-11-22 (session 2) while three other engineers were
//! building and training on the same two cores (load average about 10, so
//! roughly a fifth of the samples per second above); `--time-budget 600`
//! (`90` for the others), `--target-r-norm 0.99`:
//!
//! | run | R_norm action 0 -> trained | residual force / m g | samples, wall |
//! |---|---|---|---|
//! | kick, PD residual, 600 s | 0.871 -> 0.919 | 0.094 | 319k, 598 s |
//! | kick, PD residual, 90 s | 0.871 -> 0.882 | 0.149 | 41k, 83 s |
//! | kick, no residual (ablation), 90 s | 0.415 (falls at frame 20) -> 0.434 (falls) | 0 | 25k, 83 s |
//! | kick, learned residual (RFC ablation), 90 s | 0.415 (falls) -> 0.445 (falls) | 0.002 | 20k, 95 s |
//! | IK kick from scratch, 90 s | 0.869 -> 0.869 | 0.151 | 16k, 85 s |
//! | IK kick warm-started from the kick's policy, 90 s | 0.869 -> 0.888 (0.88 after one iteration) | 0.146 | 41k, 88 s |
//!
//! Plausibility before -> after (source at 120 Hz, output at 30 Hz; the
//! 30 Hz source gives the same skating, 0.057 m/s): IK kick foot skating
//! 0.263 -> 0.101-0.109 m/s, mean penetration 0.011 -> 0.006-0.007 m, floating
//! 0.25 -> 0; original kick: skating 0.058 -> 0.103 m/s (the planted right foot
//! pivots on the floor where the actor rose onto it; the box foot built from
//! the rest pose is rolled 2.2 rad from flat there, see
//! `physics::CharacterOptions::calibrate_feet`), penetration 0.011 -> 0.006 m,
//! floating 0.25 -> 0.
//!
//! The corrected clip is at the 30 Hz control rate; plausibility before is
//! measured on the source clip at its own rate. These figures were measured
//! when the output kept the input's height (`physics::OutputFrame::Clip`);
//! the default now stands it on y = 0, which moves penetration and floating by
//! the clip's median-frame foot level (a few mm for these clips; 5 cm for VAE
//! samples that sank, see crates/eval/README.md).

pub mod acceptance;
pub mod class;
pub mod job;
pub mod report;
pub mod rollout;
pub mod summary;
pub mod task;

pub use acceptance::{AcceptanceConfig, Criterion};
pub use class::{ClassConfig, ClassReport, train_class};
pub use job::{CorrectConfig, Outcome, ResidualSchedule, correct};
pub use report::Report;
pub use rollout::{Rollout, deterministic_rollout};

#[derive(Debug, thiserror::Error)]
pub enum CorrectError {
    #[error(transparent)]
    Physics(#[from] physics::PhysicsError),
    #[error(transparent)]
    Learning(#[from] ppo::PpoError),
    #[error(transparent)]
    Motion(#[from] motion::MotionError),
    #[error("{path}: {source}")]
    Io {
        path: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("invalid correction settings: {0}")]
    Config(String),
    #[error("{path}: not a correction report: {message}")]
    BadReport {
        path: std::path::PathBuf,
        message: String,
    },
    #[error("stopped on request before the end of training (a checkpoint was saved)")]
    Stopped,
}
