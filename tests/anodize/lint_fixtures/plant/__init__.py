"""A package whose submodule holds state (it does not import it)."""
