"""cdam_core.models.greybox."""
