"""anodize runtime."""
