"""``gsseg view``: select, edit and save objects of a run in the browser.

:mod:`gsseg.viewer.session` holds the state and every action without a browser;
:mod:`gsseg.viewer.server` serves it with viser (the optional ``viewer`` extra).
"""
