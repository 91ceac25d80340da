"""episodes subpackage."""
