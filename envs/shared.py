"""Toolkits every domain shares (the knowledge tools), in one place.

Domains build their toolkit as `CompositeToolkit(DomainTools(db), *shared_toolkits())`, so a
domain's own tool wins a name clash (see CompositeToolkit).
"""

from __future__ import annotations

from functools import lru_cache

from envs.core.tools import Toolkit


@lru_cache(maxsize=1)
def _knowledge_toolkit_class():
    try:
        from kb_service.tools import KnowledgeTools
    except ModuleNotFoundError as exc:
        if exc.name in ("kb_service.tools",):
            return None
        raise
    return KnowledgeTools


def shared_toolkits() -> list[Toolkit]:
    """The shared toolkits for a new episode: the knowledge tools over the configured KB."""
    cls = _knowledge_toolkit_class()
    if cls is None:
        return []
    return [cls()]
