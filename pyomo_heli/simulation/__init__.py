"""Float-model trim and time simulation (scipy)."""
