"""``python -m fbmbench STUDY [--option value ...]`` (:mod:`fbmbench.study`)."""
import sys

from fbmbench.study import main

sys.exit(main())
