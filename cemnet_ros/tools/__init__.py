"""Command-line tools (console scripts): cemnet-eval, cemnet-bench, cemnet-register, ..."""
