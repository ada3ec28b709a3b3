"""The user's tools: system files (:mod:`.config`), the ``anodize`` command (:mod:`.cli`),
the isolation lint (:mod:`.lint`) and named systems found by entry point (:mod:`.named`).
"""
