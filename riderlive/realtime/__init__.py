"""The real-time tick: pacing, shared-memory rings, resampling, the tick process."""
