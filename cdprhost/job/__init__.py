"""cdprhost.job"""
