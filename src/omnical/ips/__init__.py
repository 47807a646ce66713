"""Indoor positioning: beacon map, burst grouping of raw distances, multilateration."""
