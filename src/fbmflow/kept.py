"""What was made of an object that nothing writes to, kept while the object lives
(:class:`~fbmflow.kept.KeptByIdentity`): a level's divergence, a space's pattern, read by every set-up."""
from __future__ import annotations

import weakref


class KeptByIdentity:
    """``build(host)`` made at the first :meth:`~fbmflow.kept.KeptByIdentity.get` for ``host``
    and ``what`` and kept while ``host`` lives, by ``host``'s identity: for what many set-ups
    read of an object nothing writes to (a level's divergence, a space's pattern), so that it
    is made once. ``host`` must take weak references; the entry goes when ``host`` does, before
    its ``id`` can be reused."""

    def __init__(self):
        self._made: dict[tuple[int, str], object] = {}

    def get(self, host, what: str, build):
        """``build(host)``, made at the first call for ``host`` and ``what`` (which names what
        ``build`` makes of it)."""
        key = (id(host), what)
        found = self._made.get(key)
        if found is None:
            found = self._made[key] = build(host)
            weakref.finalize(host, self._made.pop, key, None)
        return found
