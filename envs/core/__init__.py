"""The environment core: tools, tasks, trajectories, action parsing, the Gymnasium env."""
