"""What the library reads: the package data (:mod:`.resources`), the table schemas (:mod:`.tables`) and the
validated table reader and atomic writers (:mod:`.io`), the characteristic sets (:mod:`.characteristics`) and the
workflow configuration with its schema defaults (:mod:`.config`). See docs/design.md."""
