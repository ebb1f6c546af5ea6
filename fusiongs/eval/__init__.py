"""Scoring: image metrics, held-out frames, the event-only floor peer, the run report."""
