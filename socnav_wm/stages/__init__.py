"""The pipeline's stages as library functions: one module per ``dvc.yaml`` stage.

Each module's ``run`` takes the validated :class:`~socnav_wm.config.Params` and plain paths, does
the stage's work inside one MLflow run (:mod:`socnav_wm.tracking`), writes its outputs atomically
and returns the one-line summary the CLI prints. ``socnav_wm.cli`` only parses options; tests
call these functions directly.

Each module imports at its top what the stage executes, so the stage's DVC dependencies are the
import closure of its module (:mod:`socnav_wm.stages.deps`, checked against ``dvc.yaml`` by the
tests).
"""
