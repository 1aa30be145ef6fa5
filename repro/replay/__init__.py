"""Replays of a run from its own files: the rebuilt scene (:mod:`.world`) and its MP4
video (:mod:`.video`)."""
