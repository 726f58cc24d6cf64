# cython: language_level=3
"""Declarations of the parts of liboctomap (Debian's liboctomap-dev) that occgp uses.

C++ names appear here only; everything above this file is snake_case.
"""

from libc.stdint cimport uint8_t, uint16_t
from libcpp cimport bool
from libcpp.string cimport string


cdef extern from "<sstream>" namespace "std" nogil:
    cdef cppclass ostream:
        pass

    cdef cppclass istream:
        bool good()
        bool fail()

    cdef cppclass ostringstream(ostream):
        ostringstream() except +
        string str() except +

    cdef cppclass istringstream(istream):
        istringstream(const string&) except +


cdef extern from "octomap/octomap.h" namespace "octomap" nogil:
    ctypedef uint16_t key_type

    cdef cppclass point3d:
        point3d() except +
        point3d(float x, float y, float z) except +
        float& x()
        float& y()
        float& z()
        point3d operator+(const point3d& other)
        point3d operator-(const point3d& other)
        point3d operator*(float factor)
        double norm()
        point3d normalized()

    cdef cppclass Pointcloud:
        Pointcloud() except +
        void reserve(size_t n) except +
        void push_back(float x, float y, float z) except +
        size_t size()

    cdef cppclass OcTreeKey:
        OcTreeKey() except +
        OcTreeKey(key_type a, key_type b, key_type c) except +
        key_type& operator[](unsigned int i)
        bool operator==(const OcTreeKey& other)

    cdef cppclass KeyRay:
        cppclass iterator:
            OcTreeKey& operator*()
            iterator& operator++()
            bool operator==(const iterator&)
            bool operator!=(const iterator&)
        KeyRay() except +
        void reset()
        size_t size()
        iterator begin()
        iterator end()

    cdef cppclass OcTreeNode:
        double getOccupancy()
        float getLogOdds()
        void setLogOdds(float value)

    cdef cppclass OccupancyOcTreeBase[NODE]:
        # What OcTree and ColorOcTree share: liboctomap's OccupancyOcTreeBase<NODE>
        # (and the OcTreeBaseImpl<NODE, ...> under it), NODE their node type.
        cppclass leaf_iterator:
            leaf_iterator() except +
            NODE& operator*()
            leaf_iterator& operator++()
            bool operator==(const leaf_iterator&)
            bool operator!=(const leaf_iterator&)
            double getSize()
            unsigned getDepth()
            const OcTreeKey& getKey()

        # sensor model
        void setProbHit(double prob)
        void setProbMiss(double prob)
        void setClampingThresMin(double prob)
        void setClampingThresMax(double prob)
        void setOccupancyThres(double prob)
        float getProbHitLog()
        float getProbMissLog()
        float getClampingThresMinLog()
        float getClampingThresMaxLog()
        float getOccupancyThresLog()

        # updates
        void insertPointCloud(const Pointcloud& scan, const point3d& sensor_origin,
                              double maxrange, bool lazy_eval, bool discretize) except +
        NODE* updateNode(const OcTreeKey& key, float log_odds_update,
                         bool lazy_eval) except +
        bool computeRayKeys(const point3d& origin, const point3d& end,
                            KeyRay& ray) except +

        # queries
        NODE* search(const OcTreeKey& key, unsigned int depth)
        bool isNodeOccupied(const NODE* node)
        bool coordToKeyChecked(const point3d& coord, OcTreeKey& key)
        double keyToCoord(key_type key, unsigned depth)
        leaf_iterator begin_leafs(unsigned char maxDepth) except +
        leaf_iterator end_leafs()

        # structure
        double getResolution()
        void setResolution(double r)
        size_t size()
        size_t getNumLeafNodes()
        size_t memoryUsage()
        void getMetricMin(double& x, double& y, double& z)
        void getMetricMax(double& x, double& y, double& z)
        void clear()

        # serialisation
        ostream& writeData(ostream& s) except +
        istream& readData(istream& s) except +
        istream& readBinaryData(istream& s) except +

    cdef cppclass OcTree(OccupancyOcTreeBase[OcTreeNode]):
        cppclass leaf_bbx_iterator:
            leaf_bbx_iterator() except +
            OcTreeNode& operator*()
            leaf_bbx_iterator& operator++()
            bool operator==(const leaf_bbx_iterator&)
            bool operator!=(const leaf_bbx_iterator&)
            double getSize()
            unsigned getDepth()
            const OcTreeKey& getKey()

        OcTree(double resolution) except +

        # updates
        OcTreeNode* setNodeValue(const OcTreeKey& key, float log_odds_value,
                                 bool lazy_eval) except +
        void updateInnerOccupancy() except +
        void useBBXLimit(bool enable)
        void setBBXMin(point3d& min)
        void setBBXMax(point3d& max)

        # queries
        bool castRay(const point3d& origin, const point3d& direction, point3d& end,
                     bool ignoreUnknownCells, double maxRange) except +
        bool getRayIntersection(const point3d& origin, const point3d& direction,
                                const point3d& center, point3d& intersection, double delta)
        bool isNodeAtThreshold(const OcTreeNode* node)
        leaf_bbx_iterator begin_leafs_bbx(const OcTreeKey& min, const OcTreeKey& max,
                                          unsigned char maxDepth) except +
        leaf_bbx_iterator end_leafs_bbx()

        # structure
        unsigned int getTreeDepth()
        void prune() except +
        void expand() except +
        void toMaxLikelihood()

        # serialisation
        ostream& writeBinaryData(ostream& s) except +


cdef extern from "octomap/ColorOcTree.h" namespace "octomap" nogil:
    cdef cppclass Color "octomap::ColorOcTreeNode::Color":
        uint8_t r
        uint8_t g
        uint8_t b

    cdef cppclass ColorOcTreeNode:
        double getOccupancy()
        float getLogOdds()
        Color getColor()
        bool isColorSet()
        void setColor(uint8_t r, uint8_t g, uint8_t b)

    cdef cppclass ColorOcTree(OccupancyOcTreeBase[ColorOcTreeNode]):
        ColorOcTree(double resolution) except +

        # colours (the .ot data block: per node float log-odds, r, g, b, child mask)
        ColorOcTreeNode* averageNodeColor(const OcTreeKey& key, uint8_t r, uint8_t g,
                                          uint8_t b)
        ColorOcTreeNode* setNodeColor(const OcTreeKey& key, uint8_t r, uint8_t g, uint8_t b)
        void updateInnerOccupancy()

        # queries
        OcTreeKey coordToKey(const point3d& coord)
