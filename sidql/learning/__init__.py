"""Learning keyframe policies: Gymnasium environment, tasks, Q-network, DQN trainer, shipped policy."""
