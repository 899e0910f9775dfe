"""Learning: the networks and losses of DDPG, TD3 and SAC, the reward curriculum, and saved agents."""
