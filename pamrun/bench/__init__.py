"""The thesis bench: the muscle, body, open-loop and capacity experiments (`pamrun muscle ...`, `pamrun body`, ...)."""
