"""estimation subpackage."""
