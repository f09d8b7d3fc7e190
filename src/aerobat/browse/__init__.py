"""``aerobat browse``: a read-only web page of the store (served locally, or exported as static files).

:class:`~aerobat.browse.site.Site` renders the pages from a store opened read-only;
:func:`~aerobat.browse.server.start` serves them on 127.0.0.1 with the standard library's HTTP
server; :meth:`Site.export` writes them to a folder. See ``docs/browse.md``.
"""

from aerobat.browse.server import Browser, start
from aerobat.browse.site import NotFound, Site

__all__ = ["Browser", "NotFound", "Site", "start"]
