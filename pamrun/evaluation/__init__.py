"""Evaluation: episodes of saved agents, gait metrics, `pamrun eval`, export, and every figure."""
