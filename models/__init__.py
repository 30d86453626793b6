"""Model files (SDF parts, task YAML, demonstrations), installed as rlfd_drake.models."""
