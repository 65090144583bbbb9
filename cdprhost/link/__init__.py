"""cdprhost.link"""
