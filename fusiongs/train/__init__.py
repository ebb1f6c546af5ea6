"""Training: settings, the data and state it optimises, one step's losses, the loop, schedules and
checkpoints."""
