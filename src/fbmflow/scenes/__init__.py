"""Built-in, validated scenes (one library for the CLI, tests, benchmarks and examples)."""
from .base import Scene, SceneResult
from .registry import SCENES, get_scene, load_scene, resume, resume_scene, run_scene

__all__ = ["Scene", "SceneResult", "SCENES", "get_scene", "load_scene", "resume", "resume_scene", "run_scene"]
