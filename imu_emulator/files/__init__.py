"""Files the program trusts or creates, handled so another user on the machine cannot steer them: the kernel cache
is loaded only if it is the running user's alone and its entries carry a keyed digest (trust); outputs are created
without following a link someone else placed, and a path a running stream holds is locked (create, locks)."""
