"""`pamrun train`: the training recipe and what it prints."""
