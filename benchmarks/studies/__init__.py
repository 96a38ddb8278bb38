"""The studies: one question each, run by ``python -m fbmbench STUDY`` (:mod:`fbmbench.study`)."""
