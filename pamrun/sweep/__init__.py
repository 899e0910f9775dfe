"""`pamrun sweep`: grids of trainings with their summaries, and Optuna searches."""
