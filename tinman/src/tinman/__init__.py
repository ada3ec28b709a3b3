"""TinMan robot system."""
