"""Benchmarks that print figures: NMPC solve times per backend on recorded problems (`solvers`),
and the closed-loop episode's real-time factor and memory (`closed_loop`)."""
