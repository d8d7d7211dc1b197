"""eden-pipe: procedural garden scenes and exact multimodal ground truth."""

__version__ = "0.1.0"
