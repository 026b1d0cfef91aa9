# mocap_autolabel: every target sets up its own virtual environment first, with only the extras it needs
# (pyproject.toml): nothing here but `make models` and `make test` installs PyTorch or ONNX tooling.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin

# What each target installs on top of the package (numpy, scipy, onnxruntime, ezc3d, c3d):
DEMO_EXTRAS  := blender
LINT_EXTRAS  := dev
# make test (what CI runs) installs every extra a test needs, so that no test skips in CI.
TEST_EXTRAS  := blender,dev,farm,report,train
BENCH_EXTRAS := blender,bench
TRAIN_EXTRAS := train
EXT_EXTRAS   := blender

.PHONY: venv demo test test-fast lint bench extension sample models clean test-bpy42

$(VENV)/.created:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	touch $@

# One stamp per set of extras; a change to pyproject.toml installs again.
# The package's bytecode is compiled once here: an editable install leaves it to the first import,
# which cannot cache it where PYTHONDONTWRITEBYTECODE is set (0.08 s of every command's start).
$(VENV)/.extras-%: pyproject.toml | $(VENV)/.created
	$(BIN)/python -m pip install -q -e ".[$*]"
	$(BIN)/python -m compileall -q addon/mocap_autolabel >/dev/null
	touch $@

## venv: the package with the bpy module (what make demo uses)
venv: $(VENV)/.extras-$(DEMO_EXTRAS)

## demo: the bundled raw synthetic take -> labels (set + trajectory voting, C3D + report) and a review scene
## (labeled markers keyed by confidence + the solved hand) -> a calibrated, solved hand rig (.blend, FBX, BVH,
## report) -> the labeled markers' gaps filled from that hand (out/demo_filled.c3d, fills marked as computed);
## also the raw take alone and beside the hand that made it; then a synthetic take of two interacting hands,
## labeled (L_/R_ names, scored against its truth) into a review scene with both solved hands; a sparse finger set
## (5 tips + a hand cluster) labeled with no model of its own, and by gmm (Alexanderson 2016) fitted on the layout's
## synthetic range of motion; a layout TOML fitted from the labeled demo take; and
## the solved hand retargeted onto a character (Rigify's human meta-rig: .blend and FBX) and exported for Unreal
demo: $(VENV)/.extras-$(DEMO_EXTRAS)
	$(BIN)/python -m mocap_autolabel info samples/demo_take.c3d
	$(BIN)/python -m mocap_autolabel label samples/demo_take.c3d --layout han19 -o out/demo_labeled.c3d --report out/demo_report.json --blend out/demo_review.blend --solve-hand
	$(BIN)/python -m mocap_autolabel info out/demo_labeled.c3d
	$(BIN)/python -m mocap_autolabel solve out/demo_labeled.c3d --layout han19 --blend out/demo_hand.blend --fbx out/demo_hand.fbx --bvh out/demo_hand.bvh --report out/demo_hand.json --save-calibration out/demo_calibration.json
	$(BIN)/python -m mocap_autolabel fill out/demo_labeled.c3d --layout han19 --calibration out/demo_calibration.json -o out/demo_filled.c3d --report out/demo_fill.json
	$(BIN)/python -m mocap_autolabel import samples/demo_take.c3d --blend out/demo.blend --summary out/demo_summary.json
	$(BIN)/python -m mocap_autolabel synth --layout han19 --frames 1200 --seed 1 -o out/demo_take.c3d --blend out/demo_truth.blend
	$(BIN)/python -m mocap_autolabel synth --hands 2 --layout han19 --frames 1200 --seed 2 -o out/demo_two_hands.c3d
	$(BIN)/python -m mocap_autolabel label out/demo_two_hands.c3d --layout han19 -o out/demo_two_hands_labeled.c3d --blend out/demo_two_hands_review.blend --solve-hand
	$(BIN)/python -m mocap_autolabel synth --layout tips5_hand3 --frames 1200 --seed 3 -o out/demo_sparse.c3d
	$(BIN)/python -m mocap_autolabel label out/demo_sparse.c3d --layout tips5_hand3 -o out/demo_sparse_labeled.c3d --report out/demo_sparse_report.json
	$(BIN)/python -m mocap_autolabel label out/demo_sparse.c3d --layout tips5_hand3 --method gmm -o out/demo_sparse_gmm.c3d
	$(BIN)/python -m mocap_autolabel layout --from out/demo_labeled.c3d -o out/demo_layout.toml
	$(BIN)/python samples/make_character.py out/character.blend
	$(BIN)/python -m mocap_autolabel solve out/demo_labeled.c3d --layout han19 --calibration out/demo_calibration.json --retarget out/character.blend --pinch --blend out/demo_character.blend --fbx out/demo_character.fbx
	$(BIN)/python -m mocap_autolabel solve out/demo_labeled.c3d --layout han19 --calibration out/demo_calibration.json --fbx out/demo_hand_ue5.fbx --bone-names ue5
	@echo "demo: open out/demo_review.blend in Blender with the add-on (Mocap tab > Review: labels coloured by confidence + the solved hand), out/demo_hand.blend (solved rig), out/demo.blend (the raw take), out/demo_truth.blend (raw take + the true hand), out/demo_two_hands_review.blend (two hands: Left hand / Right hand labels + Hand_L / Hand_R), out/demo_sparse_labeled.c3d (a sparse finger set; out/demo_sparse_gmm.c3d by gmm), out/demo_layout.toml (a layout fitted from a labeled take), out/demo_character.blend (the hand on a character's rig, NLA track 'Mocap hands') and out/demo_hand_ue5.fbx (UE5 bone names, Z up, centimetres)"

## test: ruff, then every test (real-data tests skip when ../shared/data is absent)
test: $(VENV)/.extras-$(TEST_EXTRAS) lint
	$(BIN)/python -m pytest

## test-fast: ruff, then every test but those marked slow (over about 5 s each); make test runs them all
test-fast: $(VENV)/.extras-$(TEST_EXTRAS) lint
	$(BIN)/python -m pytest -m "not slow"

lint: $(VENV)/.extras-$(LINT_EXTRAS)
	$(BIN)/ruff check .

## bench: speed and memory reports under benchmarks/reports/
bench: $(VENV)/.extras-$(BENCH_EXTRAS)
	$(BIN)/python benchmarks/import_speed.py
	$(BIN)/python benchmarks/synth_speed.py
	$(BIN)/python benchmarks/synth_realism.py
	$(BIN)/python benchmarks/per_frame.py
	$(BIN)/python benchmarks/temporal.py
	$(BIN)/python benchmarks/hand_solve.py
	$(BIN)/python benchmarks/validation.py
	$(BIN)/python benchmarks/batch.py
	$(BIN)/python benchmarks/review.py
	$(BIN)/python benchmarks/fuzz.py
	$(BIN)/python benchmarks/gap_fill.py
	$(BIN)/python benchmarks/layouts.py

## models: retrain every shipped model (set_any for every layout, then set, perm, cnn for han19 and glove13),
## seeded, then recalibrate the segment confidences; about 2.5 hours on 2 cores. set_any checkpoints itself
## (training/checkpoints/set_any.pt): stopped, it resumes where it was when run again
## (python -m training --any for that model alone; benchmarks/layouts.py measures it)
models: $(VENV)/.extras-$(TRAIN_EXTRAS)
	$(BIN)/python -m training --all
	$(BIN)/python -m training.confidence

## extension: one validated Blender extension zip per platform in dist/
extension: $(VENV)/.extras-$(EXT_EXTRAS)
	$(BIN)/python tools/build_extension.py --output-dir dist

## sample: regenerate the bundled demo take and its truth (deterministic, byte for byte)
sample: $(VENV)/.created
	$(BIN)/python -m pip install -q -e .
	$(BIN)/python -m mocap_autolabel synth --layout han19 --frames 1200 --seed 1 -o samples/demo_take.c3d

clean:
	rm -rf $(VENV) dist out .pytest_cache .ruff_cache

## test-bpy42: the Blender tests on bpy 4.2.0 (Blender 4.2 LTS: actions without slots)
test-bpy42:
	$(PYTHON) -m venv .venv42
	.venv42/bin/python -m pip install -q "bpy==4.2.0" "numpy==1.26.4" ezc3d c3d onnxruntime scipy pytest
	.venv42/bin/python -m pytest -q tests/blender/test_blender_import.py tests/core/test_cli.py \
		tests/blender/test_cli_blender.py tests/blender/test_blender_hand.py tests/blender/test_blender_solve.py \
		tests/blender/test_blender_review.py tests/blender/test_blender_scene33.py tests/blender/test_blender_pointcloud.py
