"""pamrun: learning to control robots driven by pneumatic artificial muscles."""

__version__ = "0.1.0"
