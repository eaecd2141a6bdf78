"""Hydra's config tree for kraby-study, importable so a built wheel carries it (pkg://kraby_conf)."""
