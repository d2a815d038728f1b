"""Pictures of recorded runs, never re-solved: figures after the paper's, and headless video."""
