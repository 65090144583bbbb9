"""cdprhost.tui"""
