"""kb_service package."""
import envs._runtime  # noqa: F401  (CPU-path environment defaults)

# Lazy exports keep `import kb_service` cheap (no bm25s/numba/tantivy until used).
_EXPORTS = {
    "KnowledgeBase": "kb_service.kb",
    "KBError": "kb_service.kb",
    "KBNotBuiltError": "kb_service.kb",
    "KBCorruptError": "kb_service.kb",
    "UnknownDocError": "kb_service.kb",
    "UnknownSourceError": "kb_service.kb",
    "default_kb_path": "kb_service.kb",
    "Passage": "kb_service.schema",
    "PassageRecord": "kb_service.schema",
    "KnowledgeTools": "kb_service.tools",
    "build_kb": "kb_service.ingest",
    "file_input": "kb_service.ingest",
    "PageStore": "kb_service.pages",
    "start_kb_service": "kb_service.service",
    "connect": "kb_service.service",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'kb_service' has no attribute {name!r}")
