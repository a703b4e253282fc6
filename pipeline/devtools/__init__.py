"""Developer tools (``make sync``): nothing the pipeline's commands import."""
