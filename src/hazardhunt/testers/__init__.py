"""Search methods that choose the human's actions."""
