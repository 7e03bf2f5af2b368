"""``kvp monitor``: a Textual dashboard of a KUKA robot behind KUKAVARPROXY.

Modules: :mod:`.state` (what one poll reads and how it is parsed), :mod:`.watchlist` (the saved
watch list), :mod:`.widgets` (panels and plots), :mod:`.dialogs` (input and confirmation),
:mod:`.app` (the application, its polling loop and key bindings).
"""
