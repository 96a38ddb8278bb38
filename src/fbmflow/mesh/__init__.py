"""Structured quad/hex meshes, their refinement hierarchy and boundary tags."""
from .structured import StructuredMesh, face_tags, graded_axis, q1_basis

__all__ = ["StructuredMesh", "face_tags", "graded_axis", "q1_basis"]
