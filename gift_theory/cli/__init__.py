"""The ``gift`` command: a thin shell that parses, calls the library, prints."""
