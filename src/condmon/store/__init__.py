"""(store: see the issues that introduce this stage.)"""
